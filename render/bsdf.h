// Materials at a surface point: the glTF metallic-roughness model (Lambertian diffuse, GGX specular with
// Fresnel, metals with Schlick Fresnel) and dielectric interfaces (KHR_materials_transmission / ior /
// volume), smooth or rough, thin-walled or bounding a volume.
//
// Conventions: directions point away from the surface; `wo` towards where the path came from (the
// camera side), `wi` towards the light. Values are for radiance (photon radiance) transport.
// A material with metallic 0, roughness 1 and no transmission is pure Lambertian of albedo = base colour
// (no 4 % specular layer), so that the closed-form camera equation holds exactly for diffuse targets.
#pragma once
#include <glm/glm.hpp>

#include "rng_util.h"
#include "scenes/scene.h"
#include "spectrum.h"

namespace spadgen::render {

// Unpolarised Fresnel reflectance of a smooth dielectric interface; eta = n_transmitted / n_incident.
// Returns 1 under total internal reflection.
float fresnel_dielectric(float cos_incident, float eta);

// The GGX (Trowbridge-Reitz) microfacet distribution of alpha = roughness^2: its density D of the half-vector
// at cos_h from the normal (sin2_h = sin^2 of that angle, computed apart: its precision sets a narrow lobe's),
// or of unit h in the local frame (z the normal), and a draw of a microfacet normal (local frame) with
// density D(h) cos(theta_h) from two uniform numbers.
float ggx_d(float alpha, float cos_h, float sin2_h);
float ggx_d(float alpha, const glm::vec3& h);
glm::vec3 sample_ggx(float alpha, float u, float v);

// A material resolved at one point, in the two channels (laser, ambient).
struct MaterialPoint {
  Spec base{1.0f};        // base colour (texture times factor), linear
  float metallic = 0.0f;
  float alpha = 1.0f;      // GGX alpha = roughness^2
  float transmission = 0.0f;
  float ior = 1.5f;
  bool thin_walled = true; // KHR_materials_volume thickness 0
  bool lambertian = false;
  Spec emission{0.0f};     // ambient only: photon radiance, photons/s/m^2/sr (channel 1)

  bool smooth() const { return alpha < scenes::kSmoothAlpha; }
};

// The lobes a Bsdf samples from, one at a time (Bsdf::sample picks one by its weight).
enum Lobe : int { kDiffuseLobe = 0, kSpecularLobe = 1, kTransmissionLobe = 2, kLobes = 3 };

struct BsdfSample {
  glm::vec3 wi{0.0f};
  Spec weight{0.0f};      // f cos / pdf (divided by the lobe's selection probability)
  bool delta = false;     // from a smooth (Dirac) lobe: no next-event estimation possible there
  bool transmitted = false;
  Lobe lobe = kDiffuseLobe;
};

// Each non-Dirac lobe's share of f |cos| at one direction, and the density (per steradian) with which
// Bsdf::sample draws that direction through that lobe, its selection probability included. sample()'s
// weight for a direction drawn through lobe L is f_cos[L] / pdf[L].
struct LobeValues {
  Spec f_cos[kLobes];
  float pdf[kLobes];
};

// The BSDF in a local frame around the shading normal, oriented to wo's side.
class Bsdf {
 public:
  // n_shading and n_geometric are world unit normals (any side); wo_world unit.
  // entering: whether a transmitted ray would go into the volume (wo on the front side); only matters for
  // volumes (thin-walled surfaces have air on both sides).
  Bsdf(const MaterialPoint& m, const glm::vec3& n_shading, const glm::vec3& n_geometric,
       const glm::vec3& wo_world, bool entering);

  bool has_non_delta() const { return m_.lambertian || !m_.smooth() || diffuse_weight_ > 0.0f; }
  // Whether sample() may draw a Dirac lobe (a smooth reflection or transmission).
  bool has_delta() const { return !m_.lambertian && m_.smooth() && (specular_weight_ > 0.0f || transmission_weight_ > 0.0f); }
  // f(wo, wi) |cos(wi)| over the non-Dirac lobes.
  Spec eval_cos(const glm::vec3& wi_world) const;
  // Draws 3 numbers from u (lobe choice and direction).
  BsdfSample sample(Uniform3 u) const;

  // A smooth interface with nothing but its two Dirac lobes (a clear plate): both of them, each weighted by
  // its own share (F and the transmitted 1 - F), for a path that follows both instead of drawing one. False
  // when the material has a non-Dirac part, or one of the two sends no light (total internal reflection).
  bool delta_branches(BsdfSample* reflected, BsdfSample* transmitted) const;

  // Ratio n(wi side) / n(wo side) for a transmitted direction.
  float eta() const { return eta_; }

  // The lobes at wi_world: eval_cos(wi) is the sum of f_cos, and sample() draws wi through lobe L with
  // density pdf[L] (0 for Dirac lobes, whose f_cos is 0 too).
  LobeValues lobes(const glm::vec3& wi_world) const;
  // The directions a smooth interface would send wo to: its mirror reflection, and its refraction (a
  // volume) or straight continuation (thin-walled); false when the material transmits nothing or the
  // refraction is totally reflected.
  glm::vec3 mirror_direction() const { return to_world(glm::vec3(-wo_.x, -wo_.y, wo_.z)); }
  bool refracted_direction(glm::vec3* out) const;
  // The shading normal on wo's side, and the GGX alpha.
  const glm::vec3& normal() const { return n_; }
  float alpha() const { return m_.alpha; }
  bool glossy() const { return !m_.lambertian && !m_.smooth(); }
  bool lambertian() const { return m_.lambertian; }
  bool has_diffuse() const { return m_.lambertian || diffuse_weight_ > 0.0f; }

 private:
  glm::vec3 to_local(const glm::vec3& v) const { return {glm::dot(v, t_), glm::dot(v, b_), glm::dot(v, n_)}; }
  glm::vec3 to_world(const glm::vec3& v) const { return v.x * t_ + v.y * b_ + v.z * n_; }
  Spec specular_f(const glm::vec3& wo, const glm::vec3& wi) const;
  Spec transmission_f(const glm::vec3& wo, const glm::vec3& wi) const;
  BsdfSample smooth_reflection(float p) const;
  BsdfSample smooth_transmission(float p) const;

  MaterialPoint m_;
  glm::vec3 n_, t_, b_, ng_;  // ng_: geometric normal on wo's side
  glm::vec3 wo_;              // local
  float eta_ = 1.0f;          // n_other / n_wo for volumes, 1 for thin walls
  float fresnel_o_ = 0.0f;    // dielectric Fresnel at wo (macro normal), for lobe selection
  float eta_fresnel_ = 1.5f;  // relative index the dielectric Fresnel terms use
  float g1_o_ = 1.0f;         // Smith G1(wo), shared by every evaluation
  float diffuse_weight_ = 0.0f, specular_weight_ = 0.0f, transmission_weight_ = 0.0f;
};

// Fraction of light a transmissive interface passes along a refracted path: (1 - F(cos, eta)) times
// transmission, base colour and (1 - metallic). cos is |d . n| on the side the light comes from, entering
// which side that is (eta = ior entering, 1 / ior leaving).
Spec interface_transmittance(const MaterialPoint& m, float cos_theta, bool entering);
// The share a smooth face reflects of light arriving at cos_theta from outside the material (entering) or inside
// it, as Bsdf::smooth_reflection weighs its Dirac reflection.
Spec interface_reflectance(const MaterialPoint& m, float cos_theta, bool entering);
// The same for a ray that goes straight through (shadow rays and ground-truth layers, which ignore
// refraction bending) crossing a face of normal ng in direction d. Its Fresnel terms are the light's:
// entering a volume (`volume`: the material bounds a medium) the light refracts, and `inside` becomes its
// direction in the medium; leaving it, the light meets the face at that direction's angle (and reflects
// all of it past the critical angle, as off a plate's edge), and `inside` becomes d again. Through a
// plate's parallel faces that is exact: the light leaves at the angle it came in. Start `inside` at d.
Spec straight_transmittance(const MaterialPoint& m, bool volume, const glm::vec3& d, const glm::vec3& ng, glm::vec3* inside);

}  // namespace spadgen::render
