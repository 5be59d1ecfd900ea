#include "bsdf.h"

#include <algorithm>
#include <cmath>

namespace spadgen::render {
namespace {

constexpr float kPiF = 3.14159265358979f;

float ggx_g1(float alpha, float cos_w) {
  const float c2 = std::max(cos_w * cos_w, 1e-12f);
  const float tan2 = std::max(0.0f, (1.0f - c2) / c2);
  return 2.0f / (1.0f + std::sqrt(1.0f + alpha * alpha * tan2));
}

Spec schlick(const Spec& f0, float c) {
  const float m = 1.0f - std::clamp(c, 0.0f, 1.0f);
  const float m5 = m * m * m * m * m;
  return f0 + (Spec(1.0f) - f0) * m5;
}

float max_of(const Spec& s) { return std::max(s.x, s.y); }

}  // namespace

float ggx_d(float alpha, float cos_h, float sin2_h) {
  if (cos_h <= 0.0f) return 0.0f;
  const float a2 = alpha * alpha;
  // cos^2 (a^2 - 1) + 1 = a^2 cos^2 + sin^2: near a narrow lobe's peak the left side is a difference of
  // numbers near 1 (float steps of about 1e-7 against a^2 = 6e-6 at roughness 0.05: the peak was 1.4 %
  // bright there, 7 % at 0.035); sin^2 from the vector's own small components keeps its precision.
  const float d = a2 * cos_h * cos_h + sin2_h;
  return a2 / (kPiF * d * d);
}

float ggx_d(float alpha, const glm::vec3& h) { return ggx_d(alpha, h.z, h.x * h.x + h.y * h.y); }

glm::vec3 sample_ggx(float alpha, float u, float v) {
  const float tan2 = alpha * alpha * u / std::max(1.0f - u, 1e-7f);
  const float cos_t = 1.0f / std::sqrt(1.0f + tan2);
  const float sin_t = std::sqrt(tan2) * cos_t;  // not sqrt(1 - cos^2): no cancellation in a narrow lobe
  const float phi = 2.0f * kPiF * v;
  return {sin_t * std::cos(phi), sin_t * std::sin(phi), cos_t};
}

float fresnel_dielectric(float cos_i, float eta) {
  cos_i = std::clamp(cos_i, 0.0f, 1.0f);
  // g = eta cos_t, from g^2 = eta^2 - sin_i^2 (no division); g^2 <= 0 is total internal reflection.
  const float e2 = eta * eta;
  const float g2 = e2 - 1.0f + cos_i * cos_i;
  if (g2 <= 0.0f) return 1.0f;
  const float g = std::sqrt(g2);
  // rs = (ci - eta ct) / (ci + eta ct) = (ci - g) / (ci + g); rp = (eta ci - ct) / (eta ci + ct) =
  // (e2 ci - g) / (e2 ci + g); both squares over one division.
  const float a = cos_i - g, b = cos_i + g;
  const float c = e2 * cos_i - g, d = e2 * cos_i + g;
  const float bd = b * d;
  return bd > 0.0f ? std::min(1.0f, 0.5f * (a * a * d * d + c * c * b * b) / (bd * bd)) : 1.0f;
}

Bsdf::Bsdf(const MaterialPoint& m, const glm::vec3& n_shading, const glm::vec3& n_geometric,
           const glm::vec3& wo_world, bool entering)
    : m_(m) {
  ng_ = glm::dot(wo_world, n_geometric) < 0.0f ? -n_geometric : n_geometric;
  glm::vec3 ns = glm::dot(n_shading, ng_) < 0.0f ? -n_shading : n_shading;
  // A shading normal that puts wo below the surface would make the frame meaningless.
  if (glm::dot(wo_world, ns) <= 1e-4f) ns = ng_;
  n_ = ns;
  make_basis(n_, &t_, &b_);
  wo_ = to_local(wo_world);
  wo_.z = std::max(wo_.z, 1e-6f);

  const bool volume = m_.transmission > 0.0f && !m_.thin_walled;
  eta_ = volume ? (entering ? m_.ior : 1.0f / m_.ior) : 1.0f;
  eta_fresnel_ = volume ? eta_ : m_.ior;
  if (m_.lambertian) {  // no Fresnel layer (fresnel_o_ is not used)
    diffuse_weight_ = max_of(m_.base);
    return;
  }
  fresnel_o_ = fresnel_dielectric(wo_.z, eta_fresnel_);
  if (!m_.smooth()) g1_o_ = ggx_g1(m_.alpha, wo_.z);
  const float dielectric = 1.0f - m_.metallic;
  specular_weight_ = dielectric * fresnel_o_ + (m_.metallic > 0.0f ? m_.metallic * max_of(schlick(m_.base, wo_.z)) : 0.0f);
  // Drawn with 1 - F at the mean normal, but no less than alpha (at most 1/2) when rough: past the mean
  // surface's critical angle (1 - F = 0 from inside) tilted microfacets still transmit. The weights divide
  // by these shares, so they set the variance only.
  const float transmit_share = m_.smooth() ? 1.0f - fresnel_o_ : std::max(1.0f - fresnel_o_, std::min(0.5f, m_.alpha));
  transmission_weight_ = dielectric * m_.transmission * transmit_share * max_of(m_.base);
  diffuse_weight_ = dielectric * (1.0f - m_.transmission) * (1.0f - fresnel_o_) * max_of(m_.base);
}

Spec Bsdf::specular_f(const glm::vec3& wo, const glm::vec3& wi) const {
  const glm::vec3 h = glm::normalize(wo + wi);
  const float c = glm::dot(wo, h);
  Spec f((1.0f - m_.metallic) * fresnel_dielectric(c, eta_fresnel_));
  if (m_.metallic > 0.0f) f += m_.metallic * schlick(m_.base, c);
  const float dg = ggx_d(m_.alpha, h) * g1_o_ * ggx_g1(m_.alpha, wi.z);
  return f * (dg / (4.0f * wo.z * wi.z));
}

Spec Bsdf::transmission_f(const glm::vec3& wo, const glm::vec3& wi) const {
  const Spec tint = (1.0f - m_.metallic) * m_.transmission * m_.base;
  if (m_.thin_walled) {
    // Thin-walled rough transmission: the reflection lobe mirrored through the surface.
    const glm::vec3 wr(wi.x, wi.y, -wi.z);
    const glm::vec3 h = glm::normalize(wo + wr);
    const float f_d = fresnel_dielectric(glm::dot(wo, h), m_.ior);
    const float dg = ggx_d(m_.alpha, h) * g1_o_ * ggx_g1(m_.alpha, wr.z);
    return tint * ((1.0f - f_d) * dg / (4.0f * wo.z * wr.z));
  }
  // Walter et al. 2007 in radiance mode (pbrt-v3 MicrofacetTransmission with the 1/eta^2 factor folded in).
  glm::vec3 h = glm::normalize(wo + eta_ * wi);
  if (h.z < 0.0f) h = -h;
  const float co = glm::dot(wo, h), ci = glm::dot(wi, h);
  if (co <= 0.0f || ci >= 0.0f) return Spec(0.0f);
  const float f_d = fresnel_dielectric(co, eta_);
  const float denom = co + eta_ * ci;
  const float dg = ggx_d(m_.alpha, h) * g1_o_ * ggx_g1(m_.alpha, wi.z);
  return tint * ((1.0f - f_d) * dg * std::fabs(ci) * co / (std::fabs(wi.z) * wo.z * denom * denom));
}

Spec Bsdf::eval_cos(const glm::vec3& wi_world) const {
  const glm::vec3 wi = to_local(wi_world);
  const float g = glm::dot(wi_world, ng_);
  if (g > 0.0f && wi.z > 0.0f) {
    if (m_.lambertian) return m_.base * (wi.z / kPiF);
    Spec f = m_.base * ((1.0f - m_.metallic) * (1.0f - m_.transmission) * (1.0f - fresnel_o_) / kPiF);
    if (!m_.smooth()) f += specular_f(wo_, wi);
    return f * wi.z;
  }
  if (g < 0.0f && wi.z < 0.0f && !m_.smooth() && m_.transmission > 0.0f && m_.metallic < 1.0f)
    return transmission_f(wo_, wi) * std::fabs(wi.z);
  return Spec(0.0f);
}

BsdfSample Bsdf::sample(Uniform3 u) const {
  BsdfSample s;
  const float total = diffuse_weight_ + specular_weight_ + transmission_weight_;
  if (!(total > 0.0f)) return s;
  const float pick = u.a * total;

  if (pick < diffuse_weight_) {
    s.lobe = kDiffuseLobe;
    const float p = diffuse_weight_ / total;
    const float r = std::sqrt(u.b), phi = 2.0f * kPiF * u.c;
    const glm::vec3 wi(r * std::cos(phi), r * std::sin(phi), std::sqrt(std::max(0.0f, 1.0f - u.b)));
    s.wi = to_world(wi);
    if (glm::dot(s.wi, ng_) <= 0.0f) return s;
    const float k = m_.lambertian ? 1.0f : (1.0f - m_.metallic) * (1.0f - m_.transmission) * (1.0f - fresnel_o_);
    s.weight = m_.base * (k / p);
    return s;
  }

  if (pick < diffuse_weight_ + specular_weight_) {
    s.lobe = kSpecularLobe;
    const float p = specular_weight_ / total;
    if (m_.smooth()) return smooth_reflection(p);
    const glm::vec3 h = sample_ggx(m_.alpha, u.b, u.c);
    const float c = glm::dot(wo_, h);
    if (c <= 0.0f) return s;
    const glm::vec3 wi = 2.0f * c * h - wo_;
    if (wi.z <= 0.0f) return s;
    s.wi = to_world(wi);
    if (glm::dot(s.wi, ng_) <= 0.0f) return s;
    if (!(h.z > 0.0f)) return s;
    // f cos / pdf with pdf = D h.z / (4 c): the D cancels, F G1(wo) G1(wi) c / (wo.z h.z).
    Spec f((1.0f - m_.metallic) * fresnel_dielectric(c, eta_fresnel_));
    if (m_.metallic > 0.0f) f += m_.metallic * schlick(m_.base, c);
    s.weight = f * (g1_o_ * ggx_g1(m_.alpha, wi.z) * c / (wo_.z * h.z * p));
    return s;
  }

  const float p = transmission_weight_ / total;
  s.transmitted = true;
  s.lobe = kTransmissionLobe;
  if (m_.smooth()) return smooth_transmission(p);
  const Spec tint = (1.0f - m_.metallic) * m_.transmission * m_.base;
  const glm::vec3 h = sample_ggx(m_.alpha, u.b, u.c);
  const float c = glm::dot(wo_, h);
  if (c <= 0.0f) return s;
  if (!(h.z > 0.0f)) return s;
  // f |cos| / pdf in closed form (D and the Jacobian cancel), as transmission_f over the pdf:
  //  thin-walled (the reflection lobe mirrored; pdf D h.z / (4 c)): (1 - F(c)) G1(wo) G1(wr) c / (wo.z h.z);
  //  volume (Walter et al.; pdf D h.z eta^2 |wi.h| / (c + eta wi.h)^2): (1 - F(c)) G1(wo) G1(wi) c /
  //  (wo.z h.z eta^2), the 1 / eta^2 being the radiance's compression across the interface.
  glm::vec3 wi;
  float g;
  if (m_.thin_walled) {
    const glm::vec3 wr = 2.0f * c * h - wo_;
    if (wr.z <= 0.0f) return s;
    wi = glm::vec3(wr.x, wr.y, -wr.z);
    g = (1.0f - fresnel_dielectric(c, m_.ior)) * ggx_g1(m_.alpha, wr.z);
  } else {
    const float sin2_t = (1.0f - c * c) / (eta_ * eta_);
    if (sin2_t >= 1.0f) return s;
    const float cos_t = std::sqrt(1.0f - sin2_t);
    wi = -wo_ / eta_ + (c / eta_ - cos_t) * h;
    if (wi.z >= 0.0f || glm::dot(wi, h) >= 0.0f) return s;
    g = (1.0f - fresnel_dielectric(c, eta_)) * ggx_g1(m_.alpha, wi.z) / (eta_ * eta_);
  }
  s.wi = to_world(wi);
  if (glm::dot(s.wi, ng_) >= 0.0f) return s;
  s.weight = tint * (g * g1_o_ * c / (wo_.z * h.z * p));
  return s;
}

// The Dirac branches, each chosen with probability p (its weight divided by p).
BsdfSample Bsdf::smooth_reflection(float p) const {
  BsdfSample s;
  s.lobe = kSpecularLobe;
  s.delta = true;
  s.wi = to_world(glm::vec3(-wo_.x, -wo_.y, wo_.z));
  if (glm::dot(s.wi, ng_) <= 0.0f) return s;
  const Spec f = (1.0f - m_.metallic) * Spec(fresnel_o_) + m_.metallic * schlick(m_.base, wo_.z);
  s.weight = f / p;
  return s;
}

BsdfSample Bsdf::smooth_transmission(float p) const {
  BsdfSample s;
  s.lobe = kTransmissionLobe;
  s.delta = true;
  s.transmitted = true;
  const Spec tint = (1.0f - m_.metallic) * m_.transmission * m_.base;
  if (m_.thin_walled) {
    s.wi = -to_world(wo_);
    s.weight = tint * ((1.0f - fresnel_o_) / p);
  } else {
    const float sin2_t = (1.0f - wo_.z * wo_.z) / (eta_ * eta_);
    if (sin2_t >= 1.0f) return s;
    const float cos_t = std::sqrt(1.0f - sin2_t);
    s.wi = to_world(glm::vec3(-wo_.x / eta_, -wo_.y / eta_, -cos_t));
    // Radiance is n^2-compressed across the interface; a round trip air-glass-air cancels it.
    s.weight = tint * ((1.0f - fresnel_o_) / (eta_ * eta_ * p));
  }
  if (glm::dot(s.wi, ng_) >= 0.0f) s.weight = Spec(0.0f);
  return s;
}

bool Bsdf::delta_branches(BsdfSample* reflected, BsdfSample* transmitted) const {
  if (m_.lambertian || !m_.smooth() || diffuse_weight_ > 0.0f || !(specular_weight_ > 0.0f) || !(transmission_weight_ > 0.0f))
    return false;
  // sample()'s Dirac branches with the lobe chosen for certain (p = 1).
  *reflected = smooth_reflection(1.0f);
  *transmitted = smooth_transmission(1.0f);
  const auto lit = [](const BsdfSample& b) { return b.weight.x > 0.0f || b.weight.y > 0.0f; };
  return lit(*reflected) && lit(*transmitted);
}

LobeValues Bsdf::lobes(const glm::vec3& wi_world) const {
  LobeValues out;
  for (int l = 0; l < kLobes; ++l) out.f_cos[l] = Spec(0.0f), out.pdf[l] = 0.0f;
  const float total = diffuse_weight_ + specular_weight_ + transmission_weight_;
  if (!(total > 0.0f)) return out;
  const glm::vec3 wi = to_local(wi_world);
  const float g = glm::dot(wi_world, ng_);
  if (g > 0.0f && wi.z > 0.0f) {
    if (diffuse_weight_ > 0.0f) {
      const float k = m_.lambertian ? 1.0f : (1.0f - m_.metallic) * (1.0f - m_.transmission) * (1.0f - fresnel_o_);
      out.f_cos[kDiffuseLobe] = m_.base * (k * wi.z / kPiF);
      out.pdf[kDiffuseLobe] = diffuse_weight_ / total * wi.z / kPiF;
    }
    if (!m_.smooth() && specular_weight_ > 0.0f) {
      const glm::vec3 h = glm::normalize(wo_ + wi);
      const float c = glm::dot(wo_, h);
      if (c > 0.0f && h.z > 0.0f) {
        out.f_cos[kSpecularLobe] = specular_f(wo_, wi) * wi.z;
        out.pdf[kSpecularLobe] = specular_weight_ / total * ggx_d(m_.alpha, h) * h.z / (4.0f * c);
      }
    }
    return out;
  }
  if (g < 0.0f && wi.z < 0.0f && !m_.smooth() && transmission_weight_ > 0.0f) {
    float pdf = 0.0f;
    if (m_.thin_walled) {
      const glm::vec3 wr(wi.x, wi.y, -wi.z);
      const glm::vec3 h = glm::normalize(wo_ + wr);
      const float c = glm::dot(wo_, h);
      if (c > 0.0f && h.z > 0.0f) pdf = ggx_d(m_.alpha, h) * h.z / (4.0f * c);
    } else {
      glm::vec3 h = glm::normalize(wo_ + eta_ * wi);
      if (h.z < 0.0f) h = -h;
      const float co = glm::dot(wo_, h), ci = glm::dot(wi, h);
      const float denom = co + eta_ * ci;
      if (co > 0.0f && ci < 0.0f && h.z > 0.0f)
        pdf = ggx_d(m_.alpha, h) * h.z * eta_ * eta_ * std::fabs(ci) / (denom * denom);
    }
    if (pdf > 0.0f) {
      out.f_cos[kTransmissionLobe] = transmission_f(wo_, wi) * std::fabs(wi.z);
      out.pdf[kTransmissionLobe] = transmission_weight_ / total * pdf;
    }
  }
  return out;
}

bool Bsdf::refracted_direction(glm::vec3* out) const {
  if (!(transmission_weight_ > 0.0f)) return false;
  if (m_.thin_walled) {
    *out = -to_world(wo_);
    return true;
  }
  const float sin2_t = (1.0f - wo_.z * wo_.z) / (eta_ * eta_);
  if (sin2_t >= 1.0f) return false;
  *out = to_world(glm::vec3(-wo_.x / eta_, -wo_.y / eta_, -std::sqrt(1.0f - sin2_t)));
  return true;
}

Spec interface_transmittance(const MaterialPoint& m, float cos_theta, bool entering) {
  if (!(m.transmission > 0.0f)) return Spec(0.0f);
  const float eta = m.thin_walled ? m.ior : (entering ? m.ior : 1.0f / m.ior);
  const float f = fresnel_dielectric(std::fabs(cos_theta), eta);
  return (1.0f - m.metallic) * m.transmission * (1.0f - f) * m.base;
}

Spec interface_reflectance(const MaterialPoint& m, float cos_theta, bool entering) {
  const bool volume = m.transmission > 0.0f && !m.thin_walled;
  const float eta = volume ? (entering ? m.ior : 1.0f / m.ior) : m.ior;
  const float c = std::fabs(cos_theta);
  const Spec f((1.0f - m.metallic) * fresnel_dielectric(c, eta));
  return m.metallic > 0.0f ? f + m.metallic * schlick(m.base, c) : f;
}

Spec straight_transmittance(const MaterialPoint& m, bool volume, const glm::vec3& d, const glm::vec3& ng, glm::vec3* inside) {
  const float c = glm::dot(d, ng);
  const bool entering = c < 0.0f;
  if (!volume || m.thin_walled) return interface_transmittance(m, c, entering);
  if (entering) {
    // Snell's law for the light's direction inside: eta = 1 / ior, n facing the light.
    const float eta = 1.0f / m.ior, ci = -c, k = 1.0f - eta * eta * (1.0f - ci * ci);
    *inside = glm::normalize(eta * d + (eta * ci - std::sqrt(std::max(k, 0.0f))) * ng);
    return interface_transmittance(m, c, true);
  }
  const float ci = glm::dot(*inside, ng);  // the light's angle at the face it leaves by (total reflection past critical)
  *inside = d;
  return ci > 0.0f ? interface_transmittance(m, ci, false) : Spec(0.0f);
}

}  // namespace spadgen::render
