// White-furnace tests of each BSDF: the mean sampling weight (the albedo the path tracer sees) is the
// material's known albedo where one exists and never above 1; sample() and eval_cos() agree.
#include <gtest/gtest.h>

#include <cmath>

#include "core/rng.h"
#include "render/bsdf.h"

namespace spadgen::render {
namespace {

struct Moments {
  double mean = 0, sigma_of_mean = 0;
};

// Mean of the sampling weights (channel 0) for wo at angle theta from the normal (0, 0, 1).
Moments sampled_albedo(const MaterialPoint& m, double theta, int n, uint64_t stream, bool entering = true) {
  const glm::vec3 wo(static_cast<float>(std::sin(theta)), 0.0f, static_cast<float>(std::cos(theta)));
  const Bsdf bsdf(m, {0, 0, 1}, {0, 0, 1}, wo, entering);
  Rng rng(11, RngKind::Test, stream);
  double s = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    const double w = bsdf.sample(uniform3(rng)).weight.x;
    s += w;
    s2 += w * w;
  }
  Moments r;
  r.mean = s / n;
  r.sigma_of_mean = std::sqrt(std::max(0.0, s2 / n - r.mean * r.mean) / n);
  return r;
}

// The same integral, of eval_cos over uniformly drawn directions on the sphere.
Moments evaluated_albedo(const MaterialPoint& m, double theta, int n, uint64_t stream, bool entering = true) {
  const glm::vec3 wo(static_cast<float>(std::sin(theta)), 0.0f, static_cast<float>(std::cos(theta)));
  const Bsdf bsdf(m, {0, 0, 1}, {0, 0, 1}, wo, entering);
  Rng rng(12, RngKind::Test, stream);
  double s = 0, s2 = 0;
  for (int i = 0; i < n; ++i) {
    const float z = 1.0f - 2.0f * rng.next_float(), phi = 6.2831853f * rng.next_float();
    const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
    const double w = bsdf.eval_cos({r * std::cos(phi), r * std::sin(phi), z}).x * 4.0 * 3.14159265358979;
    s += w;
    s2 += w * w;
  }
  Moments r;
  r.mean = s / n;
  r.sigma_of_mean = std::sqrt(std::max(0.0, s2 / n - r.mean * r.mean) / n);
  return r;
}

MaterialPoint lambert(float rho) {
  MaterialPoint m;
  m.base = Spec(rho);
  m.lambertian = true;
  return m;
}

MaterialPoint gltf(float base, float metallic, float roughness, float transmission = 0.0f, bool thin = true) {
  MaterialPoint m;
  m.base = Spec(base);
  m.metallic = metallic;
  m.alpha = roughness * roughness;
  m.transmission = transmission;
  m.thin_walled = thin;
  return m;
}

TEST(Bsdf, FresnelAtNormalIncidenceAndTotalInternalReflection) {
  EXPECT_NEAR(fresnel_dielectric(1.0f, 1.5f), 0.04f, 1e-6f);
  EXPECT_NEAR(fresnel_dielectric(1.0f, 1.0f / 1.5f), 0.04f, 1e-6f);
  EXPECT_EQ(fresnel_dielectric(0.5f, 1.0f / 1.5f), 1.0f);  // 60 degrees inside glass: beyond the critical angle
}

TEST(Bsdf, LambertianAlbedoIsExact) {
  for (double theta : {0.0, 0.7, 1.4}) {
    const Moments s = sampled_albedo(lambert(0.6f), theta, 10000, 1);
    EXPECT_NEAR(s.mean, 0.6, 1e-6);
    const Moments e = evaluated_albedo(lambert(0.6f), theta, 400000, 2);
    EXPECT_NEAR(e.mean, 0.6, 5 * e.sigma_of_mean);  // 5 sigma: false alarm 6e-7
  }
}

TEST(Bsdf, SmoothDielectricSplitsIntoFresnelReflectionAndTransmission) {
  const int n = 200000;
  for (double theta : {0.0, 0.5, 1.2}) {
    const float r = fresnel_dielectric(static_cast<float>(std::cos(theta)), 1.5f);
    // Thin wall: reflection R and transmission 1 - R, energy conserved exactly.
    const Moments thin = sampled_albedo(gltf(1, 0, 0, 1, true), theta, n, 3);
    EXPECT_NEAR(thin.mean, 1.0, 1e-5);
    // Entering a volume the transmitted radiance is compressed by 1/n^2 (it expands back on exit).
    // The lobe choice is a Bernoulli(R) draw between weights 1 and 1/n^2: 5 sigma of that.
    const Moments vol = sampled_albedo(gltf(1, 0, 0, 1, false), theta, n, 4);
    const double sigma = std::sqrt(r * (1 - r) / n) * (1 - 1 / 2.25);
    EXPECT_NEAR(vol.mean, r + (1 - r) / 2.25, 5 * sigma + 1e-6);
  }
}

// Every rough lobe: the mean sampling weight equals the integral of eval_cos (the sampler and the
// evaluator describe the same BSDF) and stays at or below the energy the interface can return.
TEST(Bsdf, RoughLobesSampleWhatTheyEvaluateAndConserveEnergy) {
  struct Case {
    const char* name;
    MaterialPoint m;
    double bound;
  };
  const Case cases[] = {
      {"rough metal", gltf(1.0f, 1.0f, 0.5f), 1.0},
      {"shiny metal", gltf(0.9f, 1.0f, 0.2f), 0.9 + 1e-3},
      {"plastic", gltf(0.8f, 0.0f, 0.4f), 1.0},
      {"rough thin glass", gltf(1.0f, 0.0f, 0.3f, 1.0f, true), 1.0},
      {"rough glass volume", gltf(1.0f, 0.0f, 0.3f, 1.0f, false), 0.5},  // R + (1 - R) / n^2 at most
  };
  for (const Case& c : cases)
    for (double theta : {0.2, 0.9}) {
      const Moments s = sampled_albedo(c.m, theta, 200000, 5);
      const Moments e = evaluated_albedo(c.m, theta, 800000, 6);
      const double sigma = std::hypot(s.sigma_of_mean, e.sigma_of_mean);
      // 5 sigma (false alarm 6e-7 per comparison) plus 0.5 % for glossy peaks that uniform sampling
      // resolves only slowly.
      EXPECT_NEAR(s.mean, e.mean, 5 * sigma + 0.005 * e.mean) << c.name << " theta " << theta;
      EXPECT_LE(s.mean, c.bound + 5 * s.sigma_of_mean) << c.name;
      EXPECT_GT(s.mean, 0.5 * c.bound) << c.name;
    }
}

// Inside a rough glass volume, past the critical angle of its mean surface (41.8 deg at ior 1.5), tilted
// microfacets still transmit: the sampler must draw them. It chose transmission with 1 - F at the mean
// normal, 0 there, and lost that light (a rough plate against the sky: 0.281 of it at roughness 1 where an
// independent slab Monte Carlo gives 0.349).
TEST(Bsdf, RoughGlassTransmitsPastTheCriticalAngleOfItsMeanSurface) {
  for (const float roughness : {0.3f, 0.6f, 1.0f})
    for (const double theta : {0.6, 0.9, 1.2}) {  // 34, 52 and 69 deg from inside
      const MaterialPoint m = gltf(1.0f, 0.0f, roughness, 1.0f, false);
      const Moments s = sampled_albedo(m, theta, 200000, 7, false);
      const Moments e = evaluated_albedo(m, theta, 800000, 8, false);
      const double sigma = std::hypot(s.sigma_of_mean, e.sigma_of_mean);
      // 5 sigma (false alarm 6e-7 per comparison) plus 0.5 % for the peaks uniform directions resolve slowly
      EXPECT_NEAR(s.mean, e.mean, 5 * sigma + 0.005 * e.mean) << "roughness " << roughness << " theta " << theta;
    }
}

// lobes() describes sample(): every non-Dirac draw's weight is its lobe's f_cos / pdf, and each lobe's
// density integrates, over uniformly drawn directions, to the share of draws that lobe makes and keeps.
TEST(Bsdf, LobeDensitiesAreTheSamplersDensities) {
  struct Case {
    const char* name;
    MaterialPoint m;
  };
  MaterialPoint plate = gltf(1.0f, 0.0f, 0.3f, 0.95f, false);
  const Case cases[] = {{"plastic", gltf(0.8f, 0.0f, 0.4f)},
                        {"rough thin glass", gltf(1.0f, 0.0f, 0.3f, 1.0f, true)},
                        {"rough glass volume with a diffuse part", plate},
                        {"lambertian", lambert(0.7f)}};
  for (const Case& c : cases) {
    const glm::vec3 wo(std::sin(0.5f), 0.0f, std::cos(0.5f));
    const Bsdf bsdf(c.m, {0, 0, 1}, {0, 0, 1}, wo, true);
    Rng rng(13, RngKind::Test, 1);
    const int n = 200000;
    double kept[kLobes] = {0, 0, 0};
    for (int i = 0; i < n; ++i) {
      const BsdfSample b = bsdf.sample(uniform3(rng));
      if (!(b.weight.x > 0.0f) || b.delta) continue;
      kept[b.lobe] += 1.0 / n;
      const LobeValues lv = bsdf.lobes(b.wi);
      ASSERT_GT(lv.pdf[b.lobe], 0.0f) << c.name;
      EXPECT_NEAR(lv.f_cos[b.lobe].x / lv.pdf[b.lobe], b.weight.x, 2e-4 * b.weight.x + 1e-6) << c.name;
    }
    double integral[kLobes] = {0, 0, 0}, sq[kLobes] = {0, 0, 0};
    const int m = 1000000;
    for (int i = 0; i < m; ++i) {
      const float z = 1.0f - 2.0f * rng.next_float(), phi = 6.2831853f * rng.next_float();
      const float r = std::sqrt(std::max(0.0f, 1.0f - z * z));
      const LobeValues lv = bsdf.lobes({r * std::cos(phi), r * std::sin(phi), z});
      for (int l = 0; l < kLobes; ++l) {
        const double v = lv.pdf[l] * 4.0 * 3.14159265358979;
        integral[l] += v / m, sq[l] += v * v / m;
      }
    }
    for (int l = 0; l < kLobes; ++l) {
      const double sigma = std::sqrt(std::max(0.0, sq[l] - integral[l] * integral[l]) / m + kept[l] / n);
      // 5 sigma plus 1 % for the glossy peaks that uniform directions resolve slowly.
      EXPECT_NEAR(integral[l], kept[l], 5 * sigma + 0.01 * kept[l]) << c.name << " lobe " << l;
    }
  }
}

// A narrow lobe's peak (roughness 0.035 to 0.07: the multi-object plates' 0.05) against GGX written out in
// double here: D's denominator cos^2 (a^2 - 1) + 1 cancelled in float near the peak (a^2 = 6e-6 at roughness
// 0.05 against float steps of 1e-7 near 1): a user's render of a metal plate was 1.4 % bright at the centre
// at 0.05, 7.4 % at 0.035. Within 1e-3 (the local frame's rotation in float moves wi by about 1e-7 rad).
TEST(Bsdf, ANarrowLobesPeakIsItsClosedForm) {
  for (const float roughness : {0.035f, 0.05f, 0.07f}) {
    const double alpha = double(roughness) * roughness;
    const glm::vec3 wo(std::sin(0.002f), 0.0f, std::cos(0.002f));
    const Bsdf bsdf(gltf(0.8f, 1.0f, roughness), {0, 0, 1}, {0, 0, 1}, wo, true);
    for (const double off : {0.0, 0.3, 0.7, 1.0, 2.0, 4.0}) {  // the half-vector's tilt, in units of alpha
      for (const double phi : {0.0, 1.0}) {
        const glm::dvec3 o(wo);
        const glm::dvec3 m = glm::normalize(glm::dvec3(std::tan(off * alpha) * std::cos(phi), std::tan(off * alpha) * std::sin(phi), 1.0));
        const glm::vec3 wi(glm::normalize(2.0 * glm::dot(o, m) * m - o));
        const glm::dvec3 i(wi);  // as the BSDF sees it
        const glm::dvec3 h = glm::normalize(o + i);
        const double t2 = (h.x * h.x + h.y * h.y) / (h.z * h.z), a2 = alpha * alpha;
        const double d = a2 / (3.14159265358979 * std::pow(h.z, 4) * std::pow(a2 + t2, 2));
        const auto g1 = [&](double c) { return 2 / (1 + std::sqrt(1 + a2 * (1 - c * c) / (c * c))); };
        const double c = glm::dot(o, h), f = 0.8 + 0.2 * std::pow(1 - c, 5);
        const double want = f * d * g1(o.z) * g1(i.z) / (4 * o.z * i.z) * i.z;
        EXPECT_NEAR(bsdf.eval_cos(wi).x / want, 1.0, 1e-3) << "roughness " << roughness << ", tilt " << off << " alpha, phi " << phi;
      }
    }
  }
}

// sample_ggx's draws are the inverse of GGX's distribution of tan^2 = a^2 u / (1 - u): their sine came from
// sqrt(1 - cos^2), which cancelled in a narrow lobe (tan^2 off by several per cent at alpha = 1.2e-3, where
// the weights assume the exact density).
TEST(Bsdf, NarrowLobeDrawsHaveTheirDistributionsTangents) {
  for (const float alpha : {1.2e-3f, 2.5e-3f, 0.0225f}) {
    double worst = 0.0;
    for (int k = 1; k < 1000; ++k) {
      const float u = float(k) / 1000.0f;
      const glm::dvec3 m(sample_ggx(alpha, u, 0.3f));
      const double t2 = (m.x * m.x + m.y * m.y) / (m.z * m.z), want = double(alpha) * alpha * u / (1.0 - u);
      worst = std::max(worst, std::abs(t2 / want - 1.0));
    }
    EXPECT_LT(worst, 1e-5) << "alpha " << alpha;
  }
}

TEST(Bsdf, FurnaceErrorFallsAsOneOverSqrtN) {
  // Plastic has a non-constant weight: its Monte Carlo error over N samples scales as N^-1/2.
  const MaterialPoint m = gltf(0.8f, 0.0f, 0.4f);
  const Moments ref = sampled_albedo(m, 0.6, 4000000, 20);
  double rms_small = 0, rms_large = 0;
  const int repeats = 200;
  for (int k = 0; k < repeats; ++k) {
    rms_small += std::pow(sampled_albedo(m, 0.6, 100, 100 + uint64_t(k)).mean - ref.mean, 2);
    rms_large += std::pow(sampled_albedo(m, 0.6, 1600, 1000 + uint64_t(k)).mean - ref.mean, 2);
  }
  const double ratio = std::sqrt(rms_small / rms_large);  // expected sqrt(1600 / 100) = 4
  // Over 48 seed offsets the ratio is 4.07 with a spread of 0.41 (10 %): (2.5, 5.8) is 3.8 spreads below and
  // 4.2 above; a 1 / N^(1/4) law would give 2.
  EXPECT_GT(ratio, 2.5);
  EXPECT_LT(ratio, 5.8);
}

}  // namespace
}  // namespace spadgen::render
