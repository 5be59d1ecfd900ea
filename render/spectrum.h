// spadgen renders one wavelength band at a time, monochrome: RGB quantities from the glTF (base colour,
// attenuation colour, light colour) are reduced to two scalar channels, the laser's wavelength and the
// ambient band, so that one path carries both the laser and the ambient estimate.
#pragma once
#include <glm/glm.hpp>

namespace spadgen::render {

// Channel 0: the laser wavelength; channel 1: the ambient band.
using Spec = glm::vec2;

// Weights that turn a linear RGB triple into its value at a wavelength: a piecewise-linear hat between
// nominal channel centres (blue 465 nm, green 540 nm, red 610 nm), pure blue below and pure red above.
// glTF colours carry no spectrum; this keeps a red object red under a 637 nm laser and grey stays grey.
glm::vec3 rgb_weights_at(double wavelength_m);
// The same, averaged over [centre - width/2, centre + width/2] (the ambient band) weighted by lambda: by the
// photons of an equal-energy spectrum.
glm::vec3 rgb_weights_over(double centre_m, double width_m);

// Integral of the CIE 1931 photopic luminous efficiency V(lambda) over 380-780 nm, in nm: 106.8565 from
// the 1 nm CIE table (trapezoid), 106.856895 over 360-830 nm (pbrt's CIE_Y_integral); the two differ by
// 5e-6 relative, so 106.857 is exact to the precision that matters here.
inline constexpr double kIntegralVLambdaNm = 106.857;

// Photons per second per unit of a photometric quantity (lm, lx, cd, nit) for an equal-energy spectrum
// seen through a band of width bandwidth_m around wavelength_m: an equal-energy spectrum of spectral
// density s (W/nm) has luminous value 683 lm/W * s * 106.857 nm, so s = value / (683 * 106.857); the band
// holds s * bandwidth_nm watts, i.e. s * bandwidth_nm * lambda / (h c) photons per second.
double photons_per_second_per_photometric_unit(double wavelength_m, double bandwidth_m);

}  // namespace spadgen::render
