// Physical constants and unit conversions. Everything inside spadgen is SI (metres, seconds, watts,
// photons); scene-file keys carry their unit in their name and are converted once, when parsed.
#pragma once

#include <cstdint>
#include <string>
#include <utility>

namespace spadgen {

inline constexpr double kSpeedOfLight = 299'792'458.0;    // m/s (exact, SI)
inline constexpr double kPlanck = 6.626'070'15e-34;        // J s (exact, SI)
inline constexpr double kBoltzmannEv = 8.617'333'262e-5;   // eV/K
inline constexpr double kPi = 3.141'592'653'589'793'238'46;
inline constexpr double kLuminousEfficacy = 683.0;         // lm/W at 555 nm (540 THz), SI definition

inline constexpr double kNs = 1e-9;
inline constexpr double kPs = 1e-12;
inline constexpr double kUs = 1e-6;
inline constexpr double kMm = 1e-3;
inline constexpr double kUm = 1e-6;
inline constexpr double kNm = 1e-9;

// The double nearest v's decimal (the shortest that reads back as v) times 10^k: a value in seconds said in
// microseconds without the ulp a product or quotient by 1e-6 may add (times_ten_to(1e-5, 6) is 10, where
// 1e-5 / 1e-6 is 10.000000000000002).
double times_ten_to(double v, int k);

// Energy of one photon of the given vacuum wavelength, in joules.
inline constexpr double photon_energy_J(double wavelength_m) { return kPlanck * kSpeedOfLight / wavelength_m; }

// Photons per laser pulse: N_p = P / (f_rep * h c / lambda).
inline constexpr double photons_per_pulse(double average_power_W, double repetition_rate_Hz, double wavelength_m) {
  return average_power_W / (repetition_rate_Hz * photon_energy_J(wavelength_m));
}

// Gaussian full width at half maximum <-> standard deviation.
inline constexpr double kFwhmPerSigma = 2.354'820'045'030'949'3;  // 2 sqrt(2 ln 2)

// "1.2 GB", "870 MB", "12 kB" (powers of 1000, as `spadgen info` gives sizes).
std::string bytes_text(int64_t bytes);
// Two sizes compared in a message (needed, free), as bytes_text gives them, with more digits where they would
// read the same ("need at least 2 MB ... and 2 MB is free" for 2.0 and 1.7 MB): {"2.05 MB", "1.74 MB"}.
std::pair<std::string, std::string> bytes_texts(int64_t a, int64_t b);

}  // namespace spadgen
