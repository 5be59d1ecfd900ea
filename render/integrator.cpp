#include "integrator.h"

#include "guide.h"
#include "planar_path.h"

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <cstring>
#include <limits>

#include "core/error.h"
#include "core/rng.h"
#include "core/units.h"

namespace spadgen::render {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
// Smooth interfaces do not count as bounces (a plate in front of a wall must not use up a direct-light
// render); this bounds the specular chains instead (total internal reflection inside a slab).
constexpr int kMaxDeltaEvents = 64;
// A camera path follows both branches of the first this many clear (purely Dirac) interfaces it meets, over
// all its branches in the order they are traced: a plate's two faces, and its echo inside when the branches
// traced before it left splits (through a 2 mm clear plate, the paths' spread fell from 7 % to 3e-6).
constexpr int kMaxDeltaSplits = 4;
constexpr int kMaxShadowCrossings = 64;
// A punctual light this many float ulps of a hit point's largest coordinate from the surface's plane is
// taken to lie in it (the hit point's own rounding is a few ulps).
constexpr double kPlaneRoundingUlps = 32.0;
// Guided connections aim at surfaces of GGX alpha up to this (roughness 0.2): wider lobes are found well
// enough by the BSDF's own draws.
constexpr float kGuideMaxAlpha = 0.04f;
// A vertex draws towards each ghost with this probability (the draws' density is that share of the lobe's):
// the ghost lobe's density stays far above the diffuse draw's where the ghost is, at a quarter of the rays.
constexpr double kGhostDrawShare = 0.25;
// A vertex near a plate's edge draws towards each of its light pipe's paths (edge_ghost_targets) with this
// probability: few vertices are near an edge, and its light is found by these draws almost alone (on the
// multi-object plate a quarter left 3 outliers in 24 light seeds, a half none).
constexpr float kEdgeGhostDrawShare = 0.5f;
// A vertex draws towards a plate's ghosts of more than two reflections (ghost_targets) with this
// probability: their light is the plate's reflectance (squared) weaker than the first order's, and a
// quarter cost 6 % of the multi-object run.
constexpr float kSecondGhostDrawShare = 0.1f;

inline double sqr(double x) { return x * x; }
// Lambertian vertices aim at the triangles of meshes of at most this many (plates, boxes), at most
// kMaxGlossyParts of them in a scene; and at a sliver's area only where the half-vector at its point
// nearest the mirror point, or at its point of least tilt, is within acos(kGuideMaxTilt) = 25 degrees of
// its normal. (A mesh with more, and vertex normals, is curved: scenes::Mesh::curved.)
constexpr size_t kMaxPartsPerMesh = scenes::kMaxPlanarParts;
constexpr size_t kMaxGlossyParts = 256;
constexpr double kGuideMaxTilt = 0.906;
// The same bound on the half-vector's slope m (the tangent of its tilt): sqrt(1 / 0.906^2 - 1).
constexpr double kGuideMaxSlope = 0.4672;
}  // namespace

// In steady state the returns of earlier and later pulses overlap the window the same way, so every
// periodic image inside the window receives the contribution.
void deposit(double v, double t, const TimeAxis& axis, double* bins, PixelTotals* out, double* indirect_bins) {
  out->laser_total += v;
  if (axis.bins <= 0) return;
  bool landed = false;
  const auto put = [&](double ti) {
    const int64_t b = axis.bin_of(ti);
    if (b < 0) return;
    bins[b] += v;
    if (indirect_bins) indirect_bins[b] += v;
    out->bin_lo = std::min(out->bin_lo, b);
    out->bin_hi = std::max(out->bin_hi, b + 1);
    landed = true;
  };
  if (axis.period_s > 0.0) {
    // At most window / period + 2 images land in the window; the count bounds the loop even where
    // m += 1.0 would stop changing m (t / period past 2^53) or t is not finite.
    const double m0 = std::ceil((axis.start_s - t) / axis.period_s) - 1.0;
    const double end = axis.end_s();
    const auto images = static_cast<int64_t>(std::min((end - axis.start_s) / axis.period_s, 1e15)) + 3;
    double m = m0;
    for (int64_t i = 0; i < images; ++i, m += 1.0) {
      const double ti = t + m * axis.period_s;
      if (ti >= end) break;
      put(ti);
    }
  } else {
    put(t);
  }
  if (!landed) out->out_of_window += v;
}

namespace {
// A mesh's material (null: the glTF default material, which is neither smooth nor given here).
const scenes::Material* mesh_material(const scenes::Scene& scene, const scenes::Mesh& mesh) {
  return mesh.material < 0 || size_t(mesh.material) >= scene.materials.size() ? nullptr : &scene.materials[size_t(mesh.material)];
}
// A plate's two planes: the normal of a mesh's largest faces (by area, summed over the triangles of one normal,
// either side) and the least and greatest offsets n . p of those triangles; false where they do not span two
// planes (the glossy plates of the guided connections, the rough plates of connect_laser_rough_slabs). With
// `side`, each triangle's: 0 on the lo plane, 1 on the hi one, 2 of that normal between them (within 1e-3 of the
// thickness), -1 of another normal or no area.
bool plate_planes(const scenes::Mesh& mesh, glm::dvec3* n, double* lo, double* hi, std::vector<int>* side = nullptr) {
  const auto corner = [&](size_t t, int k) { return glm::dvec3(mesh.positions[mesh.indices[3 * t + size_t(k)]]); };
  std::vector<glm::dvec3> normals, corners;  // of the triangles that have an area
  std::vector<double> areas;
  std::vector<size_t> triangle;
  for (size_t t = 0; t < mesh.triangle_count(); ++t) {
    const glm::dvec3 cr = glm::cross(corner(t, 1) - corner(t, 0), corner(t, 2) - corner(t, 0));
    const double twice = glm::length(cr);
    if (twice > 0.0) normals.push_back(cr / twice), corners.push_back(corner(t, 0)), areas.push_back(0.5 * twice), triangle.push_back(t);
  }
  double best_area = 0.0;
  for (size_t i = 0; i < normals.size(); ++i) {
    double area = 0.0;
    for (size_t j = 0; j < normals.size(); ++j)
      if (std::fabs(glm::dot(normals[i], normals[j])) > 1.0 - 1e-6) area += areas[j];
    if (area > best_area) best_area = area, *n = normals[i];
  }
  *lo = 1e300, *hi = -1e300;
  for (size_t j = 0; j < normals.size() && best_area > 0.0; ++j)
    if (std::fabs(glm::dot(*n, normals[j])) > 1.0 - 1e-6) {
      const double o = glm::dot(*n, corners[j]);
      *lo = std::min(*lo, o), *hi = std::max(*hi, o);
    }
  if (!(*hi > *lo)) return false;
  if (side) {
    side->assign(mesh.triangle_count(), -1);
    const double on_plane = 1e-3 * (*hi - *lo);
    for (size_t j = 0; j < normals.size(); ++j)
      if (std::fabs(glm::dot(*n, normals[j])) > 1.0 - 1e-6) {
        const double o = glm::dot(*n, corners[j]);
        (*side)[triangle[j]] = std::fabs(o - *lo) <= on_plane ? 0 : std::fabs(o - *hi) <= on_plane ? 1 : 2;
      }
  }
  return true;
}
// A mesh whose planar faces may mirror the laser (Integrator::mirrors_): at most kMaxPartsPerMesh triangles of a
// smooth material other than a Lambertian one.
bool mirror_mesh(const scenes::Scene& scene, const scenes::Mesh& mesh) {
  const scenes::Material* m = mesh_material(scene, mesh);
  return m && !m->lambertian() && m->smooth() && mesh.triangle_count() > 0 && mesh.triangle_count() <= kMaxPartsPerMesh;
}
// A smooth curved mesh whose surface may mirror the laser (Integrator::curved_mirrors_): of a smooth material
// other than a Lambertian one.
bool curved_mirror_mesh(const scenes::Scene& scene, const scenes::Mesh& mesh) {
  const scenes::Material* m = mesh_material(scene, mesh);
  return m && !m->lambertian() && m->smooth() && mesh.curved();
}
// A smooth curved glass mesh (a glass sphere, Integrator::curved_refractors_): of a smooth material that bounds a
// refracting volume.
bool curved_refractor_mesh(const scenes::Scene& scene, const scenes::Mesh& mesh) {
  const scenes::Material* m = mesh_material(scene, mesh);
  return m && m->refracting() && m->smooth() && mesh.curved();
}
}  // namespace

bool laser_mirrors_active(const scenes::Scene& scene) {
  return std::any_of(scene.meshes.begin(), scene.meshes.end(),
                     [&](const scenes::Mesh& mesh) { return mirror_mesh(scene, mesh) || curved_mirror_mesh(scene, mesh); });
}

bool guided_connections_active(const scenes::Scene& scene, bool enabled) {
  if (!enabled) return false;
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    MaterialPoint mp;
    mp.alpha = scene.materials[i].roughness * scene.materials[i].roughness;
    if (!mp.smooth() && mp.alpha <= kGuideMaxAlpha && scene.material_used(i)) return true;
  }
  return false;
}

namespace {

// Snell's invariant p = n_j sin(theta_j) of the path through parallel layers (thickness depth[j] along
// their normal, index[j]) whose lateral travel rho(p) = sum_j depth_j tan(theta_j) is D: rho is monotone in
// p, so Newton's steps inside a bisection bracket [0, p_max) (p_max the smallest index of a layer of some
// depth), from the first guess p0, to 1e-12 of the path's extent.
double snell_invariant(const double* depth, const double* index, int layers, double D, double p0, double p_max) {
  double extent = D;
  for (int j = 0; j < layers; ++j) extent += depth[j];
  const auto rho = [&](double p, double* slope) {
    double s = 0.0, ds = 0.0;
    for (int j = 0; j < layers; ++j) {
      const double sn = p / index[j], c = std::sqrt(std::max(0.0, 1.0 - sn * sn));
      s += depth[j] * sn / c;
      ds += depth[j] / (index[j] * c * c * c);
    }
    *slope = ds;
    return s;
  };
  double lo = 0.0, hi = p_max, p = p0;
  for (int it = 0; it < 100; ++it) {
    double slope;
    const double f = rho(p, &slope) - D;
    if (std::fabs(f) <= 1e-12 * extent) break;
    (f > 0.0 ? hi : lo) = p;
    double next = p - f / slope;
    if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
    p = next;
  }
  return p;
}

// Sample s's position in its pixel: point s of the R2 sequence (the additive recurrence of the plastic
// number's powers, Roberts 2018), rotated by the pixel's uniform shift (Cranley-Patterson). Each sample is
// uniform over the pixel, so every estimate keeps its expectation, while n consecutive samples cover the
// pixel far more evenly than n independent ones: at a silhouette the covered share's error falls from
// about 1 / sqrt(n) towards 1 / n. A target-error render's second round takes its own shift, so that its
// estimate stays independent of the first round, which decided its length.
glm::dvec2 pixel_jitter(const glm::dvec2& shift, int s) {
  constexpr double a1 = 0.75487766624669276, a2 = 0.56984029099805327;  // 1 / g, 1 / g^2, g^3 = g + 1
  const double x = shift.x + a1 * s, y = shift.y + a2 * s;
  return {x - std::floor(x), y - std::floor(y)};
}

// The medium a shadow ray from this vertex starts in: the path's own, unless it crosses the surface of
// a volume (then inside below the front face, air above it).
int shadow_medium(const Surface& sf, bool volume, bool wo_front, const glm::vec3& wi, int medium) {
  if (!volume) return medium;
  const bool wi_front = glm::dot(wi, sf.ng) > 0.0f;
  if (wi_front == wo_front) return medium;
  return wi_front ? -1 : sf.material;
}

// The laser's light arriving along unit win at a plate's edge of outward normal `out`, refracted into the
// glass (index ior): how far it moves along the plate's normal slab_n per metre it goes into the plate; -1
// when it does not enter (the laser behind the edge's plane).
double edge_climb_rate(const glm::dvec3& win, const glm::dvec3& out, const glm::dvec3& slab_n, double ior) {
  const double ce = -glm::dot(win, out), se2 = std::max(0.0, 1.0 - ce * ce) / (ior * ior);
  if (!(ce > 0.0) || !(se2 < 1.0)) return -1.0;
  return std::fabs(glm::dot(win, slab_n)) / ior / std::sqrt(1.0 - se2);
}

}  // namespace

Integrator::Integrator(const RenderStageConfig& config, const scenes::Scene& scene, const std::vector<int>& mesh_object,
                       const EmbreeScene& embree, const Shading& shading, const Camera& camera, const Laser& laser,
                       const Ambient& ambient)
    : config_(config), mesh_object_(mesh_object), embree_(embree), shading_(shading), camera_(camera), laser_(laser),
      ambient_(ambient) {
  transmission_ = scene.has_transmission();
  for (size_t i = 0; i < scene.materials.size(); ++i) refractive_ |= scene.materials[i].refracting() && scene.material_used(i);
  guided_ = guided_connections_active(scene, config.render.guided_connections);
  // The triangles of small meshes (a plate, a box) of such a material, and their slivers: two coplanar
  // triangles sharing a diagonal that make a parallelogram whose short side is under 1/20 of its long
  // one (a 2 mm edge of a 40 cm plate: 1/200). A mesh of more triangles (a curved glossy object) is left
  // to the BSDF draws, and so are all of them past kMaxGlossyParts.
  // Built whether or not the guided connections are on: a plate's edges are also laser connections.
  const bool glossy_meshes = guided_connections_active(scene, true);
  for (size_t m = 0; m < scene.meshes.size() && glossy_meshes; ++m) {
    const scenes::Mesh& mesh = scene.meshes[m];
    const MaterialPoint& mp = shading.material(mesh.material).point;
    const size_t nt = mesh.triangle_count();
    if (mp.lambertian || mp.smooth() || mp.alpha > kGuideMaxAlpha || nt > kMaxPartsPerMesh ||
        parts_.size() + nt > kMaxGlossyParts)
      continue;
    const auto corner = [&](size_t t, int k) { return glm::dvec3(mesh.positions[mesh.indices[3 * t + size_t(k)]]); };
    const size_t first_part = parts_.size();
    glm::dvec3 centroid(0.0);  // of the mesh's corners: inside a plate
    for (size_t t = 0; t < nt; ++t)
      for (int k = 0; k < 3; ++k) centroid += corner(t, k) / double(3 * nt);
    std::vector<size_t> part_of(nt, SIZE_MAX);  // triangle -> its part
    for (size_t t = 0; t < nt; ++t) {
      const glm::dvec3 e1 = corner(t, 1) - corner(t, 0), e2 = corner(t, 2) - corner(t, 0), cr = glm::cross(e1, e2);
      const double twice = glm::length(cr);
      if (twice > 0.0) part_of[t] = parts_.size(), parts_.push_back(GlossyPart{corner(t, 0), e1, e2, cr / twice, mp.alpha});
    }
    // A plate: a volume whose largest faces (by area, summed over the triangles of one normal) lie in two
    // parallel planes.
    const ResolvedMaterial& rmat = shading.material(mesh.material);
    int slab = -1;  // this mesh's plate
    glm::dvec3 plate_n(0.0);
    double lo = 0.0, hi = 0.0;
    if (rmat.volume && mp.ior != 1.0f && parts_.size() > first_part && plate_planes(mesh, &plate_n, &lo, &hi)) {
      slab = int(slabs_.size());
      slabs_.push_back(GlossySlab{plate_n, lo, hi, double(mp.ior), mp.alpha, mesh.material});
    }
    for (size_t t = 0; t < nt; ++t)
      for (size_t u = t + 1; u < nt; ++u) {
        // The corners of t not shared with u, and those shared.
        std::vector<glm::dvec3> own, shared, other;
        for (int i = 0; i < 3; ++i) {
          bool in = false;
          for (int j = 0; j < 3; ++j) in |= corner(t, i) == corner(u, j);
          (in ? shared : own).push_back(corner(t, i));
        }
        // Two distinct triangles sharing one edge (a degenerate one, two of its corners equal, has no edge
        // to share: a 2 mm plate's sides collapse where floats are coarser than that).
        if (part_of[t] == SIZE_MAX || part_of[u] == SIZE_MAX || shared.size() != 2 || own.size() != 1) continue;
        for (int j = 0; j < 3; ++j)
          if (corner(u, j) != shared[0] && corner(u, j) != shared[1]) other.push_back(corner(u, j));
        if (other.size() != 1) continue;
        const glm::dvec3 o = own[0], a = shared[0] - o, b = shared[1] - o;
        const double scale = std::max(glm::length(a), glm::length(b));
        if (glm::length(other[0] - (o + a + b)) > 1e-9 * scale) continue;  // not a parallelogram
        const glm::dvec3 cr = glm::cross(a, b);
        const double area = glm::length(cr);
        if (!(area > 0.0)) continue;
        const bool a_long = glm::length(a) >= glm::length(b);
        const glm::dvec3 lng = a_long ? a : b, shrt = a_long ? b : a;
        if (glm::length(shrt) >= 0.05 * glm::length(lng)) continue;
        // An edge of the plate: across its thickness, square to its faces.
        const GlossySlab* sl = slab >= 0 ? &slabs_[size_t(slab)] : nullptr;
        GlossyStrip st{o, lng, shrt, cr / area, area, mp.alpha};
        st.mesh = int(m);
        st.part[0] = part_of[t], st.part[1] = part_of[u];
        st.triangle[0] = uint32_t(t), st.triangle[1] = uint32_t(u);
        if (sl != nullptr && std::fabs(glm::dot(st.n, sl->n)) < 1e-6 &&
            std::fabs(std::fabs(glm::dot(shrt, sl->n)) - (sl->hi - sl->lo)) <= 1e-6 * glm::length(lng)) {
          // Lit from outside: the laser in front of the edge's plane, its light refracted in climbing
          // (along the faces' normal, per metre into the plate) at least this fast along the edge.
          const glm::dvec3 c = o + 0.5 * (lng + shrt);
          st.out = glm::dot(st.n, c - centroid) > 0.0 ? st.n : -st.n;
          st.offset = glm::dot(st.out, c);
          double rate = 1e300;
          for (const double f : {0.0, 0.5, 1.0}) {
            const double r = edge_climb_rate(glm::normalize(o + f * lng + 0.5 * shrt - laser_.position), st.out, sl->n,
                                             double(mp.ior));
            rate = r >= 0.0 ? std::min(rate, r) : 0.0;
          }
          if (rate > 0.0) {
            st.slab = slab;
            st.per_reflection = (sl->hi - sl->lo) / rate;
            edges_ = true;
          }
        }
        strips_.push_back(st);
        for (const size_t i : {part_of[t], part_of[u]})
          if (i != SIZE_MAX) parts_[i].sliver = true;
      }
  }
  // The parts' planes: a part shares the plane of the first earlier part whose plane it lies in.
  for (size_t i = 0; i < parts_.size(); ++i) {
    GlossyPart& p = parts_[i];
    const double offset = glm::dot(p.p0, p.n);
    p.plane = int(i);
    for (size_t j = 0; j < i; ++j)
      if (std::fabs(glm::dot(parts_[j].n, p.n)) > 1.0 - 1e-9 &&
          std::fabs(glm::dot(parts_[j].n, p.p0) - glm::dot(parts_[j].n, parts_[j].p0)) <= 1e-9 * (1.0 + std::fabs(offset))) {
        p.plane = parts_[j].plane;
        break;
      }
  }
  // The laser's mirrors: each plane of a small mesh (at most kMaxPartsPerMesh triangles) of a smooth material that
  // holds at least a tenth of the area of the mesh's largest plane (a plate's faces, not its edges), oriented out
  // of the mesh (away from its corners' centroid; a flat mesh as wound).
  for (size_t m = 0; m < scene.meshes.size() && mirrors_.size() < kMaxLaserMirrors; ++m) {
    const scenes::Mesh& mesh = scene.meshes[m];
    if (!mirror_mesh(scene, mesh)) continue;
    const ResolvedMaterial& rmat = shading.material(mesh.material);
    const size_t nt = mesh.triangle_count();
    const auto corner = [&](size_t t, int k) { return glm::dvec3(mesh.positions[mesh.indices[3 * t + size_t(k)]]); };
    glm::dvec3 centroid(0.0);
    for (size_t t = 0; t < nt; ++t)
      for (int k = 0; k < 3; ++k) centroid += corner(t, k) / double(3 * nt);
    struct Plane {
      glm::dvec3 n;
      double offset, area;
      std::vector<size_t> triangles;
    };
    std::vector<Plane> planes;
    for (size_t t = 0; t < nt; ++t) {
      const glm::dvec3 cr = glm::cross(corner(t, 1) - corner(t, 0), corner(t, 2) - corner(t, 0));
      const double twice = glm::length(cr);
      if (!(twice > 0.0)) continue;
      glm::dvec3 n = cr / twice;
      double offset = glm::dot(n, corner(t, 0));
      if (glm::dot(n, centroid) - offset > 1e-9 * (1.0 + std::fabs(offset))) n = -n, offset = -offset;
      auto same = std::find_if(planes.begin(), planes.end(), [&](const Plane& p) {
        return glm::dot(p.n, n) > 1.0 - 1e-6 && std::fabs(p.offset - offset) <= 1e-6 * (1.0 + std::fabs(offset));
      });
      if (same == planes.end()) planes.push_back({n, offset, 0.5 * twice, {t}});
      else same->area += 0.5 * twice, same->triangles.push_back(t);
    }
    double largest = 0.0;
    for (const Plane& p : planes) largest = std::max(largest, p.area);
    const bool volume = rmat.volume && rmat.point.ior != 1.0f;
    for (const Plane& p : planes) {
      if (p.area < 0.1 * largest || mirrors_.size() == kMaxLaserMirrors) continue;
      LaserMirror lm{p.n, p.offset, 0.0, mesh.material, volume, false, {}};
      lm.mesh = int(m);
      // (a closed mesh's face, a box's, reflects on its outer side only: from inside lies the mesh)
      lm.two_sided = !volume && std::fabs(glm::dot(p.n, centroid) - p.offset) <= 1e-6 * (1.0 + std::fabs(p.offset));
      lm.e[0] = glm::normalize(glm::cross(p.n, std::fabs(p.n.x) < 0.9 ? glm::dvec3(1, 0, 0) : glm::dvec3(0, 1, 0)));
      lm.e[1] = glm::cross(p.n, lm.e[0]);
      for (const size_t t : p.triangles)
        for (int k = 0; k < 3; ++k)
          for (int i = 0; i < 2; ++i) {
            const double o = glm::dot(lm.e[i], corner(t, k));
            lm.lo[i] = std::min(lm.lo[i], o), lm.hi[i] = std::max(lm.hi[i], o);
          }
      for (const Plane& q : planes)  // the parallel face behind, facing the other way
        if (volume && q.area >= 0.1 * largest && glm::dot(q.n, p.n) < -(1.0 - 1e-6) && p.offset + q.offset > 0.0)
          lm.depth = p.offset + q.offset;
      mirrors_.push_back(lm);
    }
  }
  for (size_t m = 0; m < scene.meshes.size(); ++m) {
    const scenes::Mesh& mesh = scene.meshes[m];
    const bool mirror = curved_mirror_mesh(scene, mesh), refractor = curved_refractor_mesh(scene, mesh);
    if (!(mirror && curved_mirrors_.size() < kMaxCurvedMeshes) && !(refractor && curved_refractors_.size() < kMaxCurvedMeshes))
      continue;
    glm::dvec3 lo(1e300), hi(-1e300);
    for (const uint32_t i : mesh.indices) lo = glm::min(lo, glm::dvec3(mesh.positions[i])), hi = glm::max(hi, glm::dvec3(mesh.positions[i]));
    const glm::dvec3 centre = 0.5 * (lo + hi);
    double inner = 1e300, outer = 0.0;
    for (const uint32_t i : mesh.indices) {
      const double r = glm::length(glm::dvec3(mesh.positions[i]) - centre);
      inner = std::min(inner, r), outer = std::max(outer, r);
    }
    const CurvedMesh c{uint32_t(m), mesh.material, centre, 0.5 * glm::length(hi - lo), inner, {}};
    if (mirror && curved_mirrors_.size() < kMaxCurvedMeshes) curved_mirrors_.push_back(c);  // (a glass sphere is both)
    if (refractor && curved_refractors_.size() < kMaxCurvedMeshes) {
      curved_refractors_.push_back(c);
      CurvedMesh& r = curved_refractors_.back();
      const double dl = glm::length(centre - laser_.position), n = medium_ior(mesh.material);
      std::vector<double> radii{inner};
      if (outer > 1.02 * inner) radii.push_back(std::sqrt(inner * outer)), radii.push_back(outer);
      for (const double R : radii) r.searches.emplace_back(dl, R, n, kCurvedRefractorSteps);
    }
  }
  // Rough plates (connect_laser_rough_slabs): small flat volumes with a rough face, their two largest parallel
  // planes. A volume is a mesh of a refracting volume material, with those of the same glTF node and index (a
  // plate frosted on one side: a mesh of each material); each plane's faces of one material.
  const auto volume = [&](const scenes::Mesh& mesh) {
    if (mesh.material < 0) return false;
    const ResolvedMaterial& rm = shading.material(mesh.material);
    const MaterialPoint& mp = rm.point;
    return rm.volume && mp.ior != 1.0f && !mp.thin_walled && mp.transmission > 0.0f && mp.metallic < 1.0f;
  };
  const auto ior = [&](size_t m) { return shading.material(scene.meshes[m].material).point.ior; };
  // The meshes `members` as one rough plate: true when they are one (a rough face; at most kMaxPartsPerMesh
  // triangles; every triangle of the largest faces' normal on one of its two planes, so not two panes one
  // behind the other, in one node or one mesh, whose gap would be taken for glass; each plane's faces of one
  // material).
  const auto add_slab = [&](const std::vector<size_t>& members) {
    scenes::Mesh merged;  // (the members' triangles, and each one's material)
    std::vector<int> materials;
    bool rough = false;
    for (const size_t g : members) {
      const scenes::Mesh& mesh = scene.meshes[g];
      rough = rough || shading.material(mesh.material).point.alpha >= kRoughCrossingAlpha;
      const uint32_t base = uint32_t(merged.positions.size());
      merged.positions.insert(merged.positions.end(), mesh.positions.begin(), mesh.positions.end());
      for (const uint32_t i : mesh.indices) merged.indices.push_back(base + i);
      materials.insert(materials.end(), mesh.triangle_count(), mesh.material);
    }
    RoughSlab sl{glm::dvec3(0.0), 0.0, 0.0, {-1, -1}};
    std::vector<int> side;
    if (!rough || merged.triangle_count() > kMaxPartsPerMesh || !plate_planes(merged, &sl.n, &sl.lo, &sl.hi, &side)) return false;
    for (size_t t = 0; t < side.size(); ++t) {
      if (side[t] < 0) continue;
      if (side[t] == 2) return false;
      int& on = sl.material[side[t]];
      if (on >= 0 && on != materials[t]) return false;
      on = materials[t];
    }
    if (sl.material[0] < 0 || sl.material[1] < 0) return false;
    rough_slabs_.push_back(sl);
    return true;
  };
  std::vector<bool> grouped(scene.meshes.size(), false);
  for (size_t m = 0; m < scene.meshes.size() && rough_slabs_.size() < kMaxRoughSlabs; ++m) {
    if (grouped[m] || !volume(scene.meshes[m])) continue;
    std::vector<size_t> group{m};
    for (size_t o = m + 1; o < scene.meshes.size() && scene.meshes[m].gltf_node >= 0; ++o)
      if (scene.meshes[o].gltf_node == scene.meshes[m].gltf_node && volume(scene.meshes[o]) && ior(o) == ior(m))
        group.push_back(o), grouped[o] = true;
    if (!add_slab(group) && group.size() > 1)  // (the node's meshes each a plate of its own, then)
      for (const size_t g : group)
        if (rough_slabs_.size() < kMaxRoughSlabs) (void)add_slab({g});
  }
  ambient_on_ = ambient.any() || shading.has_emission();
  laser_traced_ = config.trace_laser;
  laser_images_ = laser_.cos_half_angle > -1.0 &&
                  (refractive_ || !mirrors_.empty() || !curved_mirrors_.empty() || !curved_refractors_.empty());
  optics_ = config.camera.optics_transmission;
  period_opl_ = kSpeedOfLight / config.laser.repetition_rate_Hz;
  find_camera_glints();
  find_lamps_in_view();
  // The one check left here is of the interface, not of the scene file: the rows the caller describes.
  if (config.row_fill_factor.size() != static_cast<size_t>(camera.height()))
    throw Error("renderer: RenderStageConfig::row_fill_factor holds " + std::to_string(config.row_fill_factor.size()) +
                " rows, expected camera.height_px = " + std::to_string(camera.height()));
  if (!config.row_ambient_floor.empty() && config.row_ambient_floor.size() != static_cast<size_t>(camera.height()))
    throw Error("renderer: RenderStageConfig::row_ambient_floor holds " + std::to_string(config.row_ambient_floor.size()) +
                " rows, expected none or camera.height_px = " + std::to_string(camera.height()));
}

double Integrator::measurement_constant(int y) const {
  const double ff = config_.row_fill_factor[static_cast<size_t>(y)];
  const double p = camera_.pitch_m(), n = config_.camera.f_number;
  return ff * optics_ * p * p * kPi / (4.0 * n * n);
}

bool Integrator::laser_ray(const Surface& sf, LaserRay* out) const {
  const glm::dvec3 to = laser_.position - glm::dvec3(sf.p);
  out->r = glm::length(to);
  out->wid = to / out->r;
  out->intensity = laser_.intensity_towards(-out->wid);
  // Outside the beam along the straight line, the laser may still reach the vertex through a mirror or a
  // refracting plate, whose paths leave it in other directions (each tested at its own): the connection is
  // made (a wall lit through a 45-degree mirror by a 5-degree cone got none of its light; an auditor's find).
  if (!(out->intensity > 0.0) && !laser_images_) return false;
  out->wi = glm::vec3(out->wid);
  out->origin = offset_ray_origin(sf.p, sf.ng, out->wi);
  return true;
}

Spec Integrator::shadow_transmittance(const glm::vec3& origin, const glm::vec3& dir, float dist, int medium,
                                      double* extra_opl, uint64_t* rays, const FirstSegment* first,
                                      Crossings* cx) const {
  *extra_opl = 0.0;
  if (cx) cx->medium0 = medium;
  if (!first) ++*rays;
  if (!transmission_) {
    const bool blocked = first ? first->found : embree_.occluded(origin, dir, 0.0f, dist);
    return blocked ? Spec(0.0f) : Spec(1.0f);
  }
  Spec t(1.0f);
  glm::vec3 o = origin, inside = dir;
  float remaining = dist;
  for (int crossing = 0;; ++crossing) {
    if (crossing > 0) ++*rays;
    RayHit hit;
    bool found;
    if (crossing == 0 && first) {
      found = first->found;
      hit = first->hit;
    } else {
      found = embree_.intersect(o, dir, 0.0f, remaining, &hit, true);
    }
    const float seg = found ? hit.t : remaining;
    if (medium >= 0 && std::isfinite(seg)) {
      const ResolvedMaterial& rm = shading_.material(medium);
      if (rm.absorbing) t *= glm::exp(-rm.sigma * seg);
      *extra_opl += (static_cast<double>(rm.point.ior) - 1.0) * seg;
    }
    if (!found) return t;
    const Surface sf = cx ? shading_.surface(hit) : shading_.geometric(hit);
    const ResolvedMaterial& rm = shading_.material(sf.material);
    if (crossing >= kMaxShadowCrossings || !(rm.point.transmission > 0.0f)) {
      if (cx) cx->blocked = true;
      return Spec(0.0f);
    }
    const MaterialPoint mp = shading_.material_at(sf, hit);
    const float c = glm::dot(dir, sf.ng);
    const bool entering = c < 0.0f;
    t *= straight_transmittance(mp, rm.volume, dir, sf.ng, &inside);
    if (!cx && !(t.x > 0.0f || t.y > 0.0f)) return Spec(0.0f);
    if (rm.volume) medium = entering ? sf.material : -1;
    if (cx) {
      cx->refracting = cx->refracting || (rm.volume && rm.point.ior != 1.0f);
      if (cx->n == Crossings::kMax) {
        cx->planar = cx->complete = false;
      } else {
        cx->slots.c[cx->n++] = {glm::dvec3(sf.p), sf.ng, sf.material, mp, medium, hit.mesh, hit.triangle};
        // Flat-shaded (else neither refracted connection's case), and parallel to the first (else
        // connect_laser_planar's, not connect_laser_refracted's).
        if (glm::dot(sf.ns, sf.ng) < 1.0f - 1e-6f) cx->planar = false;
        if (std::fabs(glm::dot(sf.ng, cx->slots.c[0].ng)) < 1.0f - 1e-6f) cx->parallel = false;
      }
    }
    o = offset_ray_origin(sf.p, sf.ng, dir);
    remaining -= seg;
    if (!(remaining > 0.0f)) return t;
  }
}

void Integrator::trace_camera_block(int x, int y, int s_begin, int s_end, const int* begin, const int* end,
                                    CameraBlock* block, RayCounts* rays) const {
  constexpr int kPacket = EmbreeScene::kPacket;
  const int spp = s_end - s_begin;
  block->x0 = x - x % kPacket;
  block->y = y;
  block->lanes = std::min(kPacket, camera_.width() - block->x0);
  block->s0 = s_begin;
  block->spp = spp;
  const size_t n = static_cast<size_t>(spp) * kPacket;
  block->rng.clear();
  block->rng.reserve(n);
  block->dir.resize(n);
  block->hit.resize(n);
  block->found.resize(n);
  block->surface.resize(n);
  block->shadow_traced.resize(n);
  block->shadow_found.resize(n);
  block->shadow_hit.resize(n);
  block->laser.resize(n);
  const glm::vec3 cam(camera_.position());
  bool valid[kPacket], found[kPacket];
  glm::vec3 dirs[kPacket];
  // Each lane's pixel (the last one's repeated past the sensor's edge) and its shifts of the jitter
  // (pixel_jitter): the first round's, and a target-error render's second round's.
  const int first_round = config_.render.samples_per_pixel;
  const int rounds = config_.render.target_relative_error.has_value() ? 2 : 1;
  int px[kPacket];
  uint64_t pixel[kPacket];
  glm::dvec2 shift[kPacket][2];
  for (int i = 0; i < kPacket; ++i) {
    px[i] = block->x0 + std::min(i, block->lanes - 1);
    pixel[i] = static_cast<uint64_t>(y) * static_cast<uint64_t>(camera_.width()) + static_cast<uint64_t>(px[i]);
    for (int r = 0; r < rounds; ++r) {
      Rng u(config_.light_seed, RngKind::PixelJitter, pixel[i], static_cast<uint64_t>(r));
      shift[i][r].x = u.next_double();
      shift[i][r].y = u.next_double();
    }
  }
  for (int s = s_begin; s < s_end; ++s) {
    throw_if_interrupted();  // a block of many samples per pixel can take seconds
    const size_t row = static_cast<size_t>(s - s_begin) * kPacket;
    int lanes_valid = 0;
    for (int i = 0; i < kPacket; ++i) {
      const size_t j = row + static_cast<size_t>(i);
      valid[i] = i < block->lanes && (!begin || (s >= begin[i] && s < end[i]));
      lanes_valid += valid[i];
      block->rng.emplace_back(config_.light_seed, RngKind::CameraPath, pixel[i], static_cast<uint64_t>(s));
      const glm::dvec2 jit = pixel_jitter(shift[i][rounds == 2 && s >= first_round ? 1 : 0], s);
      block->dir[j] = camera_.direction(px[i] + jit.x, y + jit.y);
      dirs[i] = glm::vec3(block->dir[j]);
    }
    RayHit* hits = block->hit.data() + row;
    embree_.intersect_packet(valid, cam, dirs, 0.0f, kInf, hits, found);
    rays->camera += static_cast<uint64_t>(begin ? lanes_valid : block->lanes);  // ahead: a path's first segment
    // The laser's shadow rays from these hits, as one coherent packet.
    bool shadow[kPacket];
    glm::vec3 origins[kPacket];
    float tfar[kPacket];
    int traced = 0;
    for (int i = 0; i < kPacket; ++i) {
      const size_t j = row + static_cast<size_t>(i);
      block->found[j] = found[i];
      shadow[i] = false;
      origins[i] = cam, dirs[i] = glm::vec3(0, 0, 1), tfar[i] = 0.0f;
      if (!found[i]) continue;
      block->surface[j] = shading_.surface(hits[i]);
      LaserRay& lr = block->laser[j];
      if (!laser_traced_ || !laser_ray(block->surface[j], &lr)) continue;
      shadow[i] = true;
      origins[i] = lr.origin, dirs[i] = lr.wi, tfar[i] = float(lr.r);
      ++traced;
    }
    RayHit* shadow_hits = block->shadow_hit.data() + row;
    bool shadow_found[kPacket];
    if (traced > 0) {
      if (transmission_)
        embree_.intersect_packet(shadow, origins, dirs, 0.0f, tfar, shadow_hits, shadow_found, true);
      else
        embree_.occluded_packet(shadow, origins, dirs, 0.0f, tfar, shadow_found);
    }
    for (int i = 0; i < kPacket; ++i) {
      const size_t j = row + static_cast<size_t>(i);
      block->shadow_traced[j] = shadow[i] && traced > 0;
      block->shadow_found[j] = shadow[i] && traced > 0 && shadow_found[i];
    }
    rays->laser += static_cast<uint64_t>(traced);
  }
}

// add_samples's parts. They are inline and trace_path is always inlined, so that the compiler still sees
// one path loop in add_samples, as before the loop was split: out of line, the parts cost up to 4 % more
// instructions per bench_render image (cachegrind).

// A non-delta vertex of a camera path, with what next-event estimation needs of the path that reached it.
struct Integrator::NeeVertex {
  const Surface& sf;
  const Bsdf& bsdf;
  bool wo_front;
  bool volume;    // sf bounds a medium, so a shadow ray may start in another one than the path
  int medium;     // the path's medium at sf
  int vertices;   // non-delta vertices before this one: 0 makes the path direct
  // No reflection before this vertex (delta or not): the camera sees it directly or through transmissive
  // surfaces, so a laser connection here is light this vertex's object returns directly (ObjectLaser).
  bool seen_through;
  Spec beta;
  double opl;     // optical path from the camera centre, metres
  // Shadow rays pass straight through transmissive surfaces, so an earlier non-delta vertex has already
  // counted the light that reaches it through this surface; lighting it again through this vertex's
  // transmission lobe would count that light twice.
  bool transmission_nee;

  bool counted(const glm::vec3& wi) const { return transmission_nee || (glm::dot(wi, sf.ng) > 0.0f) == wo_front; }
  int shadow_medium_towards(const glm::vec3& wi) const { return shadow_medium(sf, volume, wo_front, wi, medium); }
};

inline bool Integrator::next_hit(const CameraBlock& block, size_t j, bool camera_ray, const glm::vec3& o,
                                const glm::vec3& d, RayHit* hit, RayCounts* rays) const {
  if (camera_ray) {
    *hit = block.hit[j];
    return block.found[j] != 0;
  }
  ++rays->bounce;
  return embree_.intersect(o, d, 0.0f, kInf, hit);
}

inline Surface Integrator::surface_at(const CameraBlock& block, size_t j, bool camera_ray, const RayHit& hit) const {
  return camera_ray ? block.surface[j] : shading_.surface(hit);
}

inline Spec Integrator::traverse(int medium, double seg, double* opl) const {
  if (medium < 0) {
    *opl += seg;
    return Spec(1.0f);
  }
  const ResolvedMaterial& rm = shading_.material(medium);
  *opl += rm.point.ior * seg;
  return rm.absorbing ? glm::exp(-rm.sigma * static_cast<float>(seg)) : Spec(1.0f);
}

struct Integrator::Shaded {
  bool wo_front;  // the side of the geometric normal the path arrives from
  Bsdf bsdf;
  bool volume;    // the surface bounds a medium
};

inline Integrator::Shaded Integrator::shade(const Surface& sf, const MaterialPoint& mp, const glm::vec3& d) const {
  const glm::vec3 wo = -d;
  const bool wo_front = glm::dot(wo, sf.ng) > 0.0f;
  return Shaded{wo_front, Bsdf(mp, sf.ns, sf.ng, wo, wo_front), shading_.material(sf.material).volume};
}

inline bool Integrator::ahead_shadow(const CameraBlock& block, size_t j, LaserRay* lr, FirstSegment* first) const {
  // The block pass traced it whenever the laser shines towards the hit, which is exactly when laser_ray
  // would succeed here, with the same computation.
  if (!block.shadow_traced[j]) return false;
  *lr = block.laser[j];
  first->found = block.shadow_found[j] != 0;
  first->hit = block.shadow_hit[j];
  return true;
}

inline void Integrator::deposit_laser_light(double value, double opl, const PixelFilm& film, bool indirect, int object) const {
  if (opl >= period_opl_) film.totals->beyond_period += value;
  deposit(value, config_.laser.emission_delay_s + opl / kSpeedOfLight, film.axis, film.bins, film.totals,
          indirect ? film.indirect_bins : nullptr);
  if (film.objects) {
    if (object >= 0) film.objects->add(object, value);
    else film.objects->indirect += value;
  }
}

inline void Integrator::deposit_laser(const NeeVertex& v, double value, double opl, const PixelFilm& film, bool reflected) const {
  // The laser is a point light, so this connection is its only strategy: each path's light is attributed
  // once, to the object of this vertex when the camera sees the vertex directly or through transmissive
  // surfaces only (smooth or rough: no reflection before it), else to the indirect rest. So the sphere
  // behind a plate returns its light directly through the plate, and a mirror image is indirect, as is an
  // echo of the laser's light between a plate's faces (`reflected`), as the camera side's half of it is.
  deposit_laser_light(value, opl, film, v.vertices > 0, v.seen_through && !reflected ? mesh_object_[size_t(v.sf.mesh)] : -1);
}

// The laser seen from v through k refracting interfaces that are parallel planes (the faces of a plate,
// flat-shaded), in media of indices n_j and thicknesses d_j along their normal (layer 0 at v, layer k at
// the laser). Snell's invariant p = n_j sin(theta_j) fixes the path: its lateral travel
// rho(p) = sum_j d_j tan(theta_j) must be the laser's lateral offset D (monotone in p: Newton with
// bisection). The irradiance at v across the path is I T dOmega / dA: with theta_L the angle at the
// laser (layer k), rho / sin(theta_L) = sum_j d_j n_k / (n_j cos theta_j) =: A and drho / dtheta_L =
// n_k cos(theta_L) sum_j d_j / (n_j cos^3 theta_j) =: B, dOmega / dA = 1 / (A B cos theta_0) (1 / r^2
// without interfaces). The path found is traced: it must cross the same surfaces, else (an edge of the
// plate between) the straight connection is used. Rough interfaces up to roughness 0.15 are crossed as smooth
// ones (their lobe's blur of the laser's direction is left out): behind a 2 mm slab the light is 1.007 of the
// rough faces' at 0.15 (docs/render.md); rougher flat ones are connect_laser_rough's.
bool Integrator::connect_laser_refracted(const NeeVertex& v, const LaserRay& lr, const Crossings& cx, double w,
                                         const PixelFilm& film, RayCounts* rays, bool echoes, double p_guess) const {
  const glm::dvec3 x(v.sf.p), L = laser_.position;
  const glm::dvec3 to = L - x;
  const double r = lr.r;
  if (!(r > 0.0)) return false;
  const Crossings::Crossing* cr = cx.slots.c;
  RefractedLayers ly;
  const int k = ly.k = cx.n;
  ly.media[0] = cx.medium0;
  for (int j = 0; j < k; ++j) ly.media[j + 1] = cr[j].medium;
  glm::dvec3 nrm(cr[0].ng);
  if (glm::dot(nrm, to) < 0.0) nrm = -nrm;
  const double H = glm::dot(to, nrm);
  double h = 0.0;
  for (int j = 0; j <= k; ++j) {
    const double next = j < k ? glm::dot(cr[j].p - x, nrm) : H;
    ly.depth[j] = next - h;
    h = next;
    if (ly.depth[j] < 0.0) return false;
    ly.index[j] = medium_ior(ly.media[j]);
    if (ly.depth[j] > 0.0) ly.p_max = std::min(ly.p_max, ly.index[j]);
  }
  const glm::dvec3 lat = to - H * nrm;
  ly.D = glm::length(lat);
  ly.nrm = nrm;
  ly.u = ly.D > 1e-12 * r ? lat / ly.D : glm::dvec3(0.0);
  const double p0 = p_guess >= 0.0 ? std::min(p_guess, ly.p_max * (1.0 - 1e-9)) : std::min(ly.index[k] * ly.D / r, 0.5 * ly.p_max);
  // The straight-through path: layer j once each.
  int layer[kMaxLaserSteps];
  bool back[kMaxLaserSteps] = {};
  for (int j = 0; j <= k; ++j) layer[j] = j;
  double p = 0.0, cs[kMaxLaserSteps];
  if (!connect_laser_along(v, ly, cx, layer, back, k + 1, p0, w, film, rays, &p, cs)) return false;
  if (!echoes) return true;
  // Its echoes: the light reflects off face b on its way and back off smooth face a < b nearer the vertex (a
  // clear plate's two faces; two plates' four, pairwise), crossing the layers between them twice more: R_b R_a
  // of the light, 2 sum n_j d_j / cos later. No camera path finds it (the reflections are Dirac or, at a rough
  // b, a vertex whose laser connection is a transmission, which NeeVertex::counted leaves to this one; then the
  // point laser): without it a clear plate's delayed echo in a transient was half its value (the camera side's
  // half), and the light through two plates 0.7 % low at ior 1.5. A rough b is crossed as smooth, as in the
  // straight-through path; a rough a's echo is the camera paths' (a vertex of reflection towards the laser).
  // Higher orders, m round trips between the same faces ((R_a R_b)^m of the light), while that share is at least
  // kEchoShareKept (echo_orders). Each echo is traced with probability min(1, (R_a R_b)^m / kEchoTraced), R the
  // faces' reflectance at the straight-through path's angles, and weighted by its inverse: unbiased, at a 6th of
  // the rays for a plate of ior 1.5 (R^2 = 0.0016), whose echoes then add about 1 % of noise to a connection's
  // light (their variance sum R_a R_b kEchoTraced). The draw is a hash of the vertex and the faces, not the
  // path's stream: a draw there would move the path's later draws, and the ambient light would no longer be the
  // bits of a run that does not trace the laser.
  for (int b = 1; b < k; ++b)
    for (int a = 0; a < b; ++a) {
      if (!cr[a].mp.smooth()) continue;
      // (inside the layer before each face: entering the face's material where that layer is not its medium)
      const double r_ab = double(interface_reflectance(cr[b].mp, float(cs[b]), ly.media[b] != cr[b].material).x) *
                          double(interface_reflectance(cr[a].mp, float(cs[a + 1]), ly.media[a + 1] != cr[a].material).x);
      const int orders = echo_orders(r_ab, (kMaxLaserSteps - (k + 1)) / (2 * (b - a)));
      for (int m = 1; m <= orders; ++m) {
        const double q = echo_drawn(v.sf.p, r_ab, m, a, b);
        if (q == 0.0) continue;
        int n = 0;
        for (int i = 0; i <= b; ++i) layer[n] = i, back[n++] = false;  // to face b
        for (int trip = 1; trip <= m; ++trip) {
          for (int i = b; i > a; --i) layer[n] = i, back[n++] = true;  // back to face a
          if (trip < m)
            for (int i = a + 1; i <= b; ++i) layer[n] = i, back[n++] = false;  // and to face b again
        }
        for (int i = a + 1; i <= k; ++i) layer[n] = i, back[n++] = false;  // and on to the laser
        (void)connect_laser_along(v, ly, cx, layer, back, n, p, w / q, film, rays);
      }
    }
  return true;
}

double Integrator::echo_drawn(const glm::vec3& p, double r_ab, int m, int a, int b) const {
  const double q = std::min(1.0, std::pow(r_ab, m) / kEchoTraced);
  if (!(q > 0.0) || (q < 1.0 && vertex_uniform(p, kEchoSalt + uint64_t(m - 1), a, b) >= q)) return 0.0;
  return q;
}

int Integrator::echo_orders(double r_ab, int fit) {
  if (!(r_ab > 0.0) || fit < 1) return 0;
  int m = 1;  // the first, always (its draw's probability carries its share)
  for (double share = r_ab * r_ab; m < fit && share >= kEchoShareKept; share *= r_ab) ++m;
  return m;
}

double Integrator::vertex_uniform(const glm::vec3& p, uint64_t salt, int a, int b) const {
  uint32_t x, y, z;
  std::memcpy(&x, &p.x, 4), std::memcpy(&y, &p.y, 4), std::memcpy(&z, &p.z, 4);
  uint64_t hash = mix64(config_.light_seed ^ salt);
  hash = mix64(hash ^ (uint64_t(x) << 32 | y));
  hash = mix64(hash ^ (uint64_t(z) << 32 | uint64_t(uint32_t(a)) << 16 | uint32_t(b)));
  return double(hash >> 11) * 0x1.0p-53;
}

// The laser's light reaching v along `n` straight segments, segment s in layer layer[s] of ly (back[s]: towards
// the vertex, after a reflection off the face on the laser's side): what connect_laser_refracted explains, for
// the unfolded path (reflections off parallel planes unfold into more of the layer). False where the path found
// does not cross the faces of the straight walk as planned (nothing deposited).
bool Integrator::connect_laser_along(const NeeVertex& v, const RefractedLayers& ly, const Crossings& cx, const int* layer,
                                     const bool* back, int n, double p0, double w, const PixelFilm& film, RayCounts* rays,
                                     double* p_out, double* cos_out) const {
  const Crossings::Crossing* cr = cx.slots.c;
  double depth[kMaxLaserSteps], index[kMaxLaserSteps];
  for (int s = 0; s < n; ++s) depth[s] = ly.depth[layer[s]], index[s] = ly.index[layer[s]];
  const double p = ly.D > 0.0 ? snell_invariant(depth, index, n, ly.D, p0, ly.p_max) : 0.0;
  if (p_out) *p_out = p;
  double sn[kMaxLaserSteps], cs[kMaxLaserSteps];
  glm::dvec3 dir[kMaxLaserSteps];
  for (int s = 0; s < n; ++s) {
    sn[s] = p / index[s], cs[s] = std::sqrt(std::max(0.0, 1.0 - sn[s] * sn[s]));
    if (!(cs[s] > 0.0)) return false;
    dir[s] = sn[s] * ly.u + (back[s] ? -cs[s] : cs[s]) * ly.nrm;
  }
  if (cos_out) std::copy_n(cs, n, cos_out);
  const glm::vec3 wi(dir[0]);
  if (!v.counted(wi)) return true;
  const Spec f = v.bsdf.eval_cos(wi);
  if (!(f.x > 0.0f)) return true;
  const double intensity = laser_.intensity_towards(-dir[n - 1]);
  if (!(intensity > 0.0)) return true;
  // Trace the path: each segment must meet the face it was planned to (forward in layer j: crossing j; back:
  // crossing j - 1), which it crosses into the next segment's layer or reflects off into the same layer.
  Spec t(1.0f);
  double opl = 0.0;
  glm::dvec3 q(v.sf.p);
  glm::vec3 qn = v.sf.ng;
  for (int s = 0; s < n; ++s) {
    const int j = layer[s];
    const double len = depth[s] / cs[s];
    const glm::vec3 dj(dir[s]);
    const glm::vec3 start = offset_ray_origin(glm::vec3(q), qn, dj);
    ++rays->refracted;
    RayHit hit;
    // To the next face: the nearest hit, with room for the float error of the faces' positions (the next
    // face but one is a layer further). To the laser: short of it.
    const float reach = s + 1 < n ? float(len * 1.01 + 1e-4) : float(len * (1.0 - 1e-6));
    const bool found = embree_.intersect(start, dj, 0.0f, reach, &hit, true);
    if (s + 1 < n) {
      if (!found) return false;
      const Crossings::Crossing& c = cr[back[s] ? j - 1 : j];
      const Surface sf = shading_.surface(hit);
      if (sf.material != c.material || std::fabs(glm::dot(sf.ng, c.ng)) < 1.0f - 1e-6f) return false;
      const bool entering = glm::dot(dj, sf.ng) < 0.0f;
      t *= layer[s + 1] == j ? interface_reflectance(c.mp, float(cs[s]), entering) : interface_transmittance(c.mp, float(cs[s]), entering);
      q = glm::dvec3(sf.p), qn = sf.ng;
    } else if (found) {
      const Surface sf = shading_.surface(hit);
      if (shading_.material(sf.material).point.transmission > 0.0f) return false;
      return true;  // blocked on the refracted path
    }
    if (ly.media[j] >= 0) {
      const ResolvedMaterial& rm = shading_.material(ly.media[j]);
      if (rm.absorbing) t *= glm::exp(-rm.sigma * float(len));
    }
    opl += index[s] * len;
  }
  if (!(t.x > 0.0f)) return true;
  double A = 0.0, B = 0.0;
  for (int s = 0; s < n; ++s) {
    A += depth[s] * index[n - 1] / (index[s] * cs[s]);
    B += depth[s] / (index[s] * cs[s] * cs[s] * cs[s]);
  }
  B *= index[n - 1] * cs[n - 1];
  const double g = 1.0 / (A * B * cs[0]);
  const double value = double(v.beta.x) * f.x * t.x * intensity * g * w;
  deposit_laser(v, value, v.opl + opl, film, n > ly.k + 1);
  return true;
}

// The laser seen from v through refracting planar faces of which some are rough (a frosted plate, or one frosted
// on one side: every face the straight walk crossed a volume's interface, at most kMaxRoughFaces of them, and
// one or more with a GGX lobe of alpha at least kRoughCrossingAlpha). The light's paths form a 2k-dimensional integral over the points y_j where they cross the faces, of
// f_v G(v, y_1) prod_j f_j G(y_j, y_j+1) I (f_j the faces' rough transmission, Walter et al. 2007; G the
// geometry terms, the laser's without a cosine). The estimate: one microfacet normal m_j per face drawn with
// density D(m_j) (m_j . n_j) (a hash of the vertex and the face, as the echoes'), the path on which Snell's law
// holds about each m_j solved (solve_planar_path, the faces shaded with m_j), and its integrand over
// |det dC / dy| prod_j D(m_j): C the tangential components of the paths' half vectors (n_in w_in + n_out w_out,
// normalised) in each face's basis, whose density in them is D (the change of variables from the points to
// the normals; C's Jacobian by central differences). A smoother face's lobe is a Dirac one in C at its normal
// (m_j = n_j, its f_j without D: its BSDF at kDeltaAlpha over that D). Each f_j holds its D(m_j), which cancels: the estimate's
// spread comes from the Fresnel, shadowing and geometry factors only, at any roughness (specular manifold
// sampling with offset normals, Zeltner et al. 2020, with one solve per draw). Nothing is deposited where the
// drawn normals admit no path across the same faces; one solve per draw, from the straight line's points (8 starts
// spread over a plate found no second path in 393,216 draws at roughness 0.7). The echoes between rough faces are
// not connected (the camera paths' through their lobes).
void Integrator::connect_laser_rough(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film, RayCounts* rays) const {
  const Crossings::Crossing* cr = cx.slots.c;
  const int k = cx.n;
  const glm::dvec3 x(v.sf.p), L = laser_.position;
  PlanarFace faces[kMaxRoughFaces];
  glm::dvec3 start[kMaxRoughFaces], tb[kMaxRoughFaces][2];
  double index[kMaxRoughFaces + 1], D_prod = 1.0;
  int media[kMaxRoughFaces + 1];
  bool delta[kMaxRoughFaces];
  media[0] = cx.medium0;
  for (int j = 0; j < k; ++j) {
    const glm::dvec3 nj(cr[j].ng);
    make_basis(nj, &tb[j][0], &tb[j][1]);
    // The microfacet normal: density D(m) (m . n) (tan^2 theta = alpha^2 u / (1 - u)); a smoother face's the face's
    // own normal, its D that of kDeltaAlpha there (the BSDF's at the solved path, evaluated with that alpha).
    delta[j] = !(cr[j].mp.alpha >= kRoughCrossingAlpha);
    glm::dvec3 m = nj;
    if (delta[j]) {
      D_prod *= double(ggx_d(kDeltaAlpha, 1.0f, 0.0f));
    } else {
      const double a = double(cr[j].mp.alpha), u = vertex_uniform(v.sf.p, kRoughSalt, j, 0), phi = 2.0 * kPi * vertex_uniform(v.sf.p, kRoughSalt, j, 1);
      const double tan2 = a * a * u / (1.0 - u), c = 1.0 / std::sqrt(1.0 + tan2), s = c * std::sqrt(tan2);
      m = s * std::cos(phi) * tb[j][0] + s * std::sin(phi) * tb[j][1] + c * nj;
      D_prod *= double(ggx_d(cr[j].mp.alpha, float(c), float(s * s)));
    }
    faces[j] = PlanarFace{cr[j].p, nj};
    faces[j].shaded = true, faces[j].m = m;
    start[j] = cr[j].p;
    media[j + 1] = cr[j].medium;
  }
  if (!(D_prod > 0.0)) return;
  for (int s = 0; s <= k; ++s) index[s] = medium_ior(media[s]);
  PlanarPath path;
  if (!solve_planar_path(x, L, faces, index, k, start, &path)) return;
  const double intensity = laser_.intensity_towards(-path.d[k]);
  if (!(intensity > 0.0)) return;
  const glm::vec3 wi(path.d[0]);
  if (!v.counted(wi)) return;
  const Spec f = v.bsdf.eval_cos(wi);
  if (!(f.x > 0.0f)) return;
  // Each segment must meet its face first (material and plane), the last one nothing (another transmissive surface
  // on the way is not this connection's); each face's BSDF there.
  int material[kMaxRoughFaces];
  glm::vec3 ng[kMaxRoughFaces];
  for (int j = 0; j < k; ++j) material[j] = cr[j].material, ng[j] = cr[j].ng;
  FaceHits hits;
  const FaceHit* met = hits.f;
  if (trace_planar_path(v.sf.p, v.sf.ng, path, material, ng, nullptr, nullptr, &rays->refracted, hits.f) != PathTrace::Clear) return;
  double value = double(f.x), opl = 0.0;
  for (int s = 0; s <= k; ++s) {
    if (s < k) {
      const Surface& sf = met[s].sf;
      const glm::vec3 wo = -glm::vec3(path.d[s]);
      MaterialPoint mp = shading_.material_at(sf, met[s].hit);
      if (delta[s]) mp.alpha = kDeltaAlpha;
      const Bsdf b(mp, sf.ns, sf.ng, wo, glm::dot(wo, sf.ng) > 0.0f);
      value *= double(b.eval_cos(glm::vec3(path.d[s + 1])).x) * std::fabs(glm::dot(glm::dvec3(wo), glm::dvec3(sf.ns)));
    }
    if (media[s] >= 0) {
      const ResolvedMaterial& rm = shading_.material(media[s]);
      if (rm.absorbing) value *= double(std::exp(-rm.sigma.x * float(path.len[s])));
    }
    value /= path.len[s] * path.len[s];
    opl += index[s] * path.len[s];
  }
  if (!(value > 0.0)) return;
  // C's Jacobian in the points' coordinates along each face's basis, by central differences.
  const auto half_vectors = [&](const glm::dvec3* y, double* C) {
    for (int j = 0; j < k; ++j) {
      const glm::dvec3 to_v = glm::normalize((j == 0 ? x : y[j - 1]) - y[j]), to_l = glm::normalize((j == k - 1 ? L : y[j + 1]) - y[j]);
      glm::dvec3 h = glm::normalize(index[j] * to_v + index[j + 1] * to_l);
      if (glm::dot(h, glm::dvec3(cr[j].ng)) < 0.0) h = -h;
      C[2 * j] = glm::dot(h, tb[j][0]), C[2 * j + 1] = glm::dot(h, tb[j][1]);
    }
  };
  double J[2 * kMaxRoughFaces][2 * kMaxRoughFaces];
  glm::dvec3 y[kMaxRoughFaces];
  std::copy_n(path.y, k, y);
  for (int j = 0; j < k; ++j)
    for (int e = 0; e < 2; ++e) {
      const double eps = 1e-6 * (path.len[j] + path.len[j + 1]);
      double Cp[2 * kMaxRoughFaces], Cm[2 * kMaxRoughFaces];
      y[j] = path.y[j] + eps * tb[j][e];
      half_vectors(y, Cp);
      y[j] = path.y[j] - eps * tb[j][e];
      half_vectors(y, Cm);
      y[j] = path.y[j];
      for (int i = 0; i < 2 * k; ++i) J[i][2 * j + e] = (Cp[i] - Cm[i]) / (2.0 * eps);
    }
  double det = 1.0;  // (Gaussian elimination, partial pivoting)
  for (int c = 0; c < 2 * k; ++c) {
    int p = c;
    for (int r = c + 1; r < 2 * k; ++r)
      if (std::fabs(J[r][c]) > std::fabs(J[p][c])) p = r;
    if (!(std::fabs(J[p][c]) > 0.0)) return;
    if (p != c) std::swap(J[p], J[c]), det = -det;
    det *= J[c][c];
    for (int r = c + 1; r < 2 * k; ++r) {
      const double g = J[r][c] / J[c][c];
      for (int i = c; i < 2 * k; ++i) J[r][i] -= g * J[c][i];
    }
  }
  value *= intensity / (std::fabs(det) * D_prod);
  if (!std::isfinite(value)) return;
  deposit_laser(v, double(v.beta.x) * value * w, v.opl + opl, film, false);
}

// The laser's light through each rough plate (rough_slabs_) that the straight walk to it did not cross: a vertex
// beside a rough plate's shadow, or in it behind something else, which the plate's rough transmission lights
// all the same (behind a 3 mm plate of roughness 0.7, up to 0.25 of the bare wall's light beyond the shadow's
// edge). The plate's two planes are the crossings (the straight line's points on them the solve's start), as
// connect_laser_rough takes them; its trace keeps the paths that meet the plate's faces.
void Integrator::connect_laser_rough_slabs(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film,
                                           RayCounts* rays) const {
  const glm::dvec3 x(v.sf.p), L = laser_.position;
  for (const RoughSlab& sl : rough_slabs_) {
    if (std::any_of(cx.slots.c, cx.slots.c + cx.n,
                    [&](const Crossings::Crossing& c) { return c.material == sl.material[0] || c.material == sl.material[1]; }))
      continue;
    const double ox = glm::dot(sl.n, x), ol = glm::dot(sl.n, L);
    if (!((ox < sl.lo && ol > sl.hi) || (ox > sl.hi && ol < sl.lo))) continue;  // (the plate between them)
    Crossings ex;
    ex.n = 2;
    ex.medium0 = -1;
    ex.refracting = true;
    const bool up = ox < sl.lo;  // (from the lo plane to the hi one)
    const double planes[2] = {up ? sl.lo : sl.hi, up ? sl.hi : sl.lo};
    const int materials[2] = {sl.material[up ? 0 : 1], sl.material[up ? 1 : 0]};
    for (int j = 0; j < 2; ++j) {
      Crossings::Crossing& c = ex.slots.c[j];
      c.p = x + (planes[j] - ox) / (ol - ox) * (L - x);
      c.ng = glm::vec3(sl.n);
      c.material = materials[j];
      c.mp = shading_.material(materials[j]).point;
      c.medium = j == 0 ? materials[0] : -1;
      c.mesh = 0, c.triangle = 0;
    }
    connect_laser_rough(v, ex, w, film, rays);
  }
}

// Whether connect_laser_rough takes the straight walk's crossings: each the interface of a volume, at most
// kMaxRoughFaces of them, one or more with a GGX lobe of alpha at least kRoughCrossingAlpha.
bool Integrator::rough_crossings(const Crossings& cx) const {
  // (each crossing changes the medium, and the chain ends in air, where the laser is: a walk past a plate's very
  // edge recorded one face from air to air, and the solve through it gave 1e11 times a connection's light)
  if (!(cx.n >= 1 && cx.n <= kMaxRoughFaces) || cx.slots.c[cx.n - 1].medium != -1) return false;
  bool rough = false;
  for (int j = 0; j < cx.n; ++j) {
    const MaterialPoint& mp = cx.slots.c[j].mp;
    if (cx.slots.c[j].medium == (j == 0 ? cx.medium0 : cx.slots.c[j - 1].medium) || mp.thin_walled ||
        !(mp.transmission > 0.0f) || !(mp.metallic < 1.0f))
      return false;
    rough = rough || mp.alpha >= kRoughCrossingAlpha;
  }
  return rough;
}

// The laser seen from v through planar faces that are not all parallel: the path that obeys Snell's law at
// each (solve_planar_path), traced as connect_laser_along traces its own, lit with the path bundle's spread.
// Fresnel transmittance at each face at its own angle, Beer-Lambert over each segment. With `echoes`, the
// light reflected off face b on its way and back off smooth face a < b too, as connect_laser_refracted traces
// it between parallel faces (drawn with the same probability, from the main path's angles, and to the same
// orders): its chain of faces 0..b, then b-1..a and a+1..b once per round trip, a+1..k-1, reflecting off b and
// a, solved as a whole.
bool Integrator::connect_laser_planar(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film,
                                      RayCounts* rays, bool echoes) const {
  static_assert(3 * Crossings::kMax <= kMaxPlanarFaces);
  const Crossings::Crossing* cr = cx.slots.c;
  const int k = cx.n;
  PlanarFace faces[kMaxPlanarFaces];
  glm::dvec3 start[kMaxPlanarFaces];
  double index[kMaxPlanarFaces + 1];
  int media[kMaxPlanarFaces + 1], material[kMaxPlanarFaces];
  glm::vec3 ng[kMaxPlanarFaces];
  bool reflect[kMaxPlanarFaces] = {};
  const auto layer_medium = [&](int layer) { return layer == 0 ? cx.medium0 : cr[layer - 1].medium; };
  media[0] = cx.medium0;
  for (int j = 0; j < k; ++j) {
    faces[j] = {cr[j].p, glm::dvec3(cr[j].ng)};
    start[j] = cr[j].p;
    media[j + 1] = cr[j].medium;
    material[j] = cr[j].material, ng[j] = cr[j].ng;
  }
  for (int s = 0; s <= k; ++s) index[s] = medium_ior(media[s]);
  PlanarPath path;
  if (!solve_planar_path(glm::dvec3(v.sf.p), laser_.position, faces, index, k, start, &path)) return false;
  if (!deposit_planar_path(v, path, material, ng, index, media, nullptr, w, film, &rays->refracted)) return false;
  if (!echoes) return true;
  const PlanarPath main = path;
  for (int b = 1; b < k; ++b)
    for (int a = 0; a < b; ++a) {
      if (!cr[a].mp.smooth()) continue;
      const auto reflectance = [&](int face, int segment) {
        const float c = float(std::fabs(glm::dot(main.d[segment], faces[face].n)));
        return double(interface_reflectance(cr[face].mp, c, layer_medium(segment) != cr[face].material).x);
      };
      const double r_ab = reflectance(b, b) * reflectance(a, a + 1);
      const int orders = echo_orders(r_ab, (kMaxPlanarFaces - k) / (2 * (b - a)));
      for (int m = 1; m <= orders; ++m) {
        const double q = echo_drawn(v.sf.p, r_ab, m, a, b);
        if (q == 0.0) continue;
        // The chain: each entry a face of the straight walk, whether the path reflects off it, and the layer after.
        int n = 0;
        PlanarFace cf[kMaxPlanarFaces];
        const auto add = [&](int face, bool off, int layer_after) {
          cf[n] = faces[face];
          start[n] = main.y[face];
          material[n] = cr[face].material, ng[n] = cr[face].ng;
          reflect[n] = off;
          media[n + 1] = layer_medium(layer_after);
          ++n;
        };
        media[0] = cx.medium0;
        for (int j = 0; j < b; ++j) add(j, false, j + 1);  // to face b
        for (int trip = 1; trip <= m; ++trip) {
          if (trip > 1)
            for (int j = a + 1; j < b; ++j) add(j, false, j + 1);  // to face b again
          add(b, true, b);                                       // off it
          for (int j = b - 1; j > a; --j) add(j, false, j);      // back to face a
          add(a, true, a + 1);                                   // off it
        }
        for (int j = a + 1; j < k; ++j) add(j, false, j + 1);  // and on to the laser
        for (int s = 0; s <= n; ++s) index[s] = medium_ior(media[s]);
        if (solve_planar_path(glm::dvec3(v.sf.p), laser_.position, cf, index, n, start, &path, reflect))
          (void)deposit_planar_path(v, path, material, ng, index, media, reflect, w / q, film, &rays->refracted);
      }
    }
  return true;
}

namespace {
// The Integrator's FaceTracker: a point that left its triangle moves onto the triangle of the same mesh met from
// the point before it (the vertex x, of geometric normal x_ng, for the first) towards it, from the same side, at
// the trace's crossing with that triangle's plane (in double). Its rays counted in *rays; toward_light: traced
// as the light's (a single-sided face culled from behind as the light sees it: crossings), else as a camera
// path's (a mirror met from its front).
class MeshTracker final : public FaceTracker {
 public:
  MeshTracker(const EmbreeScene& embree, const Shading& shading, const glm::vec3& x_ng, uint64_t* rays, bool toward_light)
      : embree_(embree), shading_(shading), x_ng_(x_ng), rays_(rays), toward_light_(toward_light) {}
  bool track(const glm::dvec3& x, glm::dvec3* y, PlanarFace* f, int n) const override {
    glm::dvec3 prev = x;
    glm::vec3 prev_n = x_ng_;
    for (int j = 0; j < n; prev = y[j], prev_n = glm::vec3(f[j].n), ++j) {
      if (!f[j].shaded) continue;
      const glm::dvec3 e = y[j] - f[j].p;
      const double a = glm::dot(f[j].dual[0], e), b = glm::dot(f[j].dual[1], e);
      if (a >= 0.0 && b >= 0.0 && a + b <= 1.0) continue;
      const glm::vec3 origin = offset_ray_origin(glm::vec3(prev), prev_n, glm::vec3(y[j] - prev));
      const glm::dvec3 dir = glm::normalize(y[j] - glm::dvec3(origin));
      ++*rays_;
      RayHit hit;
      if (!embree_.intersect(origin, glm::vec3(dir), 0.0f, std::numeric_limits<float>::infinity(), &hit, toward_light_) ||
          hit.mesh != f[j].mesh)
        return false;
      PlanarFace g;
      if (!shading_.face(hit.mesh, hit.triangle, &g) || (glm::dot(dir, g.n) < 0.0) != (glm::dot(dir, f[j].n) < 0.0))
        return false;
      const double t = glm::dot(g.p - glm::dvec3(origin), g.n) / glm::dot(dir, g.n);
      y[j] = glm::dvec3(origin) + t * dir;
      f[j] = g;
    }
    return true;
  }

 private:
  const EmbreeScene& embree_;
  const Shading& shading_;
  glm::vec3 x_ng_;
  uint64_t* rays_;
  bool toward_light_;
};
}  // namespace

// The laser seen from v through faces of which some are shaded (triangles of smooth meshes, a glass sphere): the
// path that obeys Snell's law at each about its shading normal (solve_planar_path), each triangle its plane with
// its corner normals interpolated (and extended beyond its edges within a Newton step). From the triangles the
// straight walk crossed, a step's point that leaves its triangle is moved onto the triangle the path meets there
// (traced from the point before it: the same mesh, met from the same side), as the manifold walk's projection.
// Fresnel at the shading normals, as the camera's paths refract. Where no path is found nothing is deposited: no
// refracted light reaches v that way (a glass sphere's shadow beside its focused light), or the walk missed it.
void Integrator::connect_laser_shaded(const NeeVertex& v, const Crossings& cx, double w,
                                      const PixelFilm& film, RayCounts* rays) const {
  constexpr int kMax = Crossings::kMax;
  const Crossings::Crossing* cr = cx.slots.c;
  const int k = cx.n;
  PlanarFace faces[kMax];
  glm::dvec3 start[kMax];
  double index[kMax + 1];
  int media[kMax + 1], material[kMax];
  glm::vec3 ng[kMax];
  bool shaded[kMax];
  media[0] = cx.medium0;
  for (int j = 0; j < k; ++j) {
    if (!shading_.face(cr[j].mesh, cr[j].triangle, &faces[j])) return;
    start[j] = cr[j].p;
    media[j + 1] = cr[j].medium;
    material[j] = cr[j].material, ng[j] = cr[j].ng, shaded[j] = faces[j].shaded;
  }
  for (int s = 0; s <= k; ++s) index[s] = medium_ior(media[s]);
  const MeshTracker tracker(embree_, shading_, v.sf.ng, &rays->refracted, true);
  PlanarPath path;
  if (!solve_planar_path(glm::dvec3(v.sf.p), laser_.position, faces, index, k, start, &path, nullptr, &tracker)) return;
  (void)deposit_planar_path(v, path, material, ng, index, media, nullptr, w, film, &rays->refracted, shaded);
}

Integrator::PathTrace Integrator::trace_planar_path(const glm::vec3& origin, const glm::vec3& origin_n, const PlanarPath& path,
                                                    const int* material, const glm::vec3* ng, const bool* reflect,
                                                    const bool* shaded, uint64_t* rays, FaceHit* faces) const {
  const int k = path.k;
  glm::vec3 q = origin, qn = origin_n;
  for (int s = 0; s <= k; ++s) {
    const glm::vec3 ds(path.d[s]);
    const glm::vec3 start_s = offset_ray_origin(q, qn, ds);
    ++*rays;
    RayHit hit;
    const float reach = s < k ? float(path.len[s] * 1.01 + 1e-4) : float(path.len[s] * (1.0 - 1e-6));
    // (towards a face it reflects off, the segment is seen as a camera path's: a single-sided mirror is met from
    // its front, not culled as the light would see it from behind)
    const bool found = embree_.intersect(start_s, ds, 0.0f, reach, &hit, !(s < k && reflect && reflect[s]));
    if (s == k) {
      if (!found) return PathTrace::Clear;
      return shading_.material(shading_.surface(hit).material).point.transmission > 0.0f ? PathTrace::Transmissive
                                                                                         : PathTrace::Blocked;
    }
    if (!found) return PathTrace::Astray;
    const Surface sf = shading_.surface(hit);
    // (in the plane planned: a face of the same material and orientation in another, a box's other side, is not
    // it; along the face the trace drifts by its origins' offsets, about 1e-5 m. A shaded face's point may lie on
    // its triangle's edge, the trace meeting the triangle beside it: near the point planned is enough)
    if (sf.material != material[s]) return PathTrace::Astray;
    if (shaded && shaded[s] ? glm::length(glm::dvec3(sf.p) - path.y[s]) > 1e-4 * (1.0 + glm::length(path.y[s]))
                            : std::fabs(glm::dot(sf.ng, ng[s])) < 1.0f - 1e-6f ||
                                  std::fabs(glm::dot(glm::dvec3(ng[s]), glm::dvec3(sf.p) - path.y[s])) > 1e-5 * (1.0 + glm::length(path.y[s])))
      return PathTrace::Astray;
    faces[s] = FaceHit{sf, hit};
    q = sf.p, qn = sf.ng;
  }
  return PathTrace::Clear;
}

// A shaded face's normal at the solved point y[s]: Snell's law (and the law of reflection, index[s] = index[s + 1])
// puts index[s] d[s] - index[s + 1] d[s + 1] along it there, to the solve's 1e-12. The traced segments' hits are
// 1e-5 m or more away (each segment starts from the last hit, offset along its face's normal by kOffsetUlps ulps:
// 3e-5 m at 1 m from the frame's origin), where a 0.1 m sphere's interpolated normal is about 2e-4 rad off: the
// Fresnel factors there were 2.9e-4 high through a glass sphere at 60 degrees (2e-3 at ior 1.3). fallback: where
// the faces' indices match (no Fresnel factor) and the vector vanishes.
namespace {
glm::vec3 solved_normal(const PlanarPath& path, const double* index, int s, const glm::vec3& fallback) {
  const glm::dvec3 m = index[s] * path.d[s] - index[s + 1] * path.d[s + 1];
  const double l = glm::length(m);
  return l > 1e-9 ? glm::vec3(m / l) : fallback;
}
}  // namespace

Spec Integrator::planar_path_throughput(const PlanarPath& path, const FaceHit* faces, const double* index, const int* media,
                                        const bool* reflect, const bool* shaded, double* opl) const {
  const int k = path.k;
  Spec t(1.0f);
  *opl = 0.0;
  for (int s = 0; s <= k; ++s) {
    if (s < k) {
      const Surface& sf = faces[s].sf;
      const glm::vec3 ds(path.d[s]);
      const float c = glm::dot(ds, sf.ng);
      const MaterialPoint mp = shading_.material_at(sf, faces[s].hit);
      const float cf = shaded && shaded[s] ? std::copysign(std::fabs(glm::dot(ds, solved_normal(path, index, s, sf.ns))), c) : c;
      t *= reflect && reflect[s] ? interface_reflectance(mp, cf, c < 0.0f) : interface_transmittance(mp, std::fabs(cf), c < 0.0f);
    }
    if (media[s] >= 0) {
      const ResolvedMaterial& rm = shading_.material(media[s]);
      if (rm.absorbing) t *= glm::exp(-rm.sigma * float(path.len[s]));
    }
    *opl += index[s] * path.len[s];
  }
  return t;
}

bool Integrator::deposit_planar_path(const NeeVertex& v, const PlanarPath& path, const int* material, const glm::vec3* ng,
                                     const double* index, const int* media, const bool* reflect, double w,
                                     const PixelFilm& film, uint64_t* rays, const bool* shaded) const {
  const int k = path.k;
  const double intensity = laser_.intensity_towards(-path.d[k]);
  if (!(intensity > 0.0)) return true;
  const glm::vec3 wi(path.d[0]);
  if (!v.counted(wi)) return true;
  const Spec f = v.bsdf.eval_cos(wi);
  if (!(f.x > 0.0f)) return true;
  // Each segment must meet its face first (material and orientation), the last one nothing opaque.
  FaceHits hits;
  const FaceHit* faces = hits.f;
  switch (trace_planar_path(v.sf.p, v.sf.ng, path, material, ng, reflect, shaded, rays, hits.f)) {
    case PathTrace::Clear: break;
    case PathTrace::Blocked: return true;  // blocked on the refracted path
    case PathTrace::Astray:
    case PathTrace::Transmissive: return false;
  }
  double opl = 0.0;
  const Spec t = planar_path_throughput(path, faces, index, media, reflect, shaded, &opl);
  if (!(t.x > 0.0f)) return true;
  const double value = double(v.beta.x) * f.x * t.x * intensity * path.spread * w;
  deposit_laser(v, value, v.opl + opl, film, reflect && std::find(reflect, reflect + k, true) != reflect + k);
  return true;
}

// The paths to a point L's image (the laser's, a lamp's) in each smooth planar face (mirrors_) with x and L on its
// outer side: off the face itself, and, behind a plate's face, off its other face through this one twice (refracted
// both ways). No camera path finds either (a Dirac reflection, then a point): connect_laser_mirrors deposits the
// laser's at a vertex x, find_camera_glints them at the camera centre, find_lamps_in_view the lamps' there.
template <class Sink>
void Integrator::for_each_mirror_path(const glm::dvec3& x, const glm::dvec3& L, const glm::vec3* draw_at, Sink&& sink) const {
  for (const LaserMirror& m : mirrors_) {
    glm::dvec3 n = m.n;
    double offset = m.offset, sx = glm::dot(n, x) - offset, sl = glm::dot(n, L) - offset;
    if (m.two_sided && sx < 0.0 && sl < 0.0) n = -n, offset = -offset, sx = -sx, sl = -sl;  // a sheet's other side
    if (!(sx > 0.0 && sl > 0.0)) continue;
    // Whether a path that meets the face between points p and q of its plane may meet it within its extent
    // (else no ray is traced).
    const auto on_face = [&](const glm::dvec3& p, const glm::dvec3& q) {
      for (int i = 0; i < 2; ++i) {
        const double a = glm::dot(m.e[i], p), b = glm::dot(m.e[i], q), margin = 1e-6 * (1.0 + std::fabs(a));
        if (std::max(a, b) < m.lo[i] - margin || std::min(a, b) > m.hi[i] + margin) return false;
      }
      return true;
    };
    const MaterialPoint& mp = shading_.material(m.material).point;
    const glm::vec3 face_n(n);
    // Off the face: the straight line to the laser's image across it, whose 1 / r^2 is the spread.
    const glm::dvec3 image = L - 2.0 * sl * n;
    const glm::dvec3 at = x + sx / (sx + sl) * (image - x);
    MirrorPath out;
    out.mirror = int(&m - mirrors_.data());
    PlanarPath& path = out.path;
    if (on_face(at, at)) {
      path.k = 1;
      path.y[0] = at;
      path.len[0] = glm::length(at - x), path.len[1] = glm::length(L - at);
      if (path.len[0] > 0.0 && path.len[1] > 0.0) {
        path.d[0] = (at - x) / path.len[0], path.d[1] = (L - at) / path.len[1];
        const double r = path.len[0] + path.len[1];
        path.spread = 1.0 / (r * r);
        out.material[0] = m.material, out.normals[0] = face_n, out.reflect[0] = true;
        out.index[0] = out.index[1] = 1.0, out.media[0] = out.media[1] = -1;
        out.trips = -1;
        sink(static_cast<const MirrorPath&>(out), 1.0);  // (q: the probability it was drawn with)
      }
    }
    if (!(m.depth > 0.0)) continue;
    // Off the face behind, through this one twice, after `m` more round trips inside (off the face behind, then
    // this one from inside): the layers of parallel faces unfolded (air sx, the plate's thickness 2 m + 2 times,
    // air sl), solved for Snell's invariant p as connect_laser_refracted solves them. The refracted path enters the
    // face between where the unfolded straight line does and `at` (the glass's index between 1 and infinity).
    // Round trips carry the first path's light times the inside reflectance squared per trip (at the first path's
    // angle): each is traced with probability min(1, that share / 0.1), weighted by its inverse, as
    // connect_laser_refracted draws its echoes (unbiased; a plate of ior 1.5 traces a 60th of the first trips
    // near normal incidence; at 0.01 the light transport beside a clear plate took 1.7 times the time without
    // the mirrors, at 0.1 1.5), while the share is at least 1e-6 (8 trips at most).
    const glm::dvec3 to = L - x;
    const glm::dvec3 lat = to - glm::dot(to, n) * n;
    const double D = glm::length(lat), ior = double(mp.ior);
    double share = 1.0, r_inside = 0.0;
    for (int trips = 0; trips <= 8 && share >= kEchoShareKept; ++trips) {
      constexpr double kTraced = 0.1;
      const double q = draw_at == nullptr ? 1.0 : std::min(1.0, share / kTraced);
      if (q < 1.0 && vertex_uniform(*draw_at, kEchoSalt, 100 + trips, int(&m - mirrors_.data())) >= q) {
        share *= r_inside * r_inside;
        continue;
      }
      const int glass = 2 * trips + 2, segments = glass + 2, k = segments - 1;
      const double unfolded = sx + sl + double(glass) * m.depth;
      if (!on_face(x + sx / unfolded * (lat - unfolded * n), at)) break;
      const glm::dvec3 u = D > 1e-12 * unfolded ? lat / D : glm::dvec3(0.0);
      double depth[kMaxPlanarFaces + 1];
      double* index = out.index;
      int* media = out.media;
      int* material = out.material;
      bool* off = out.reflect;
      glm::vec3* normals = out.normals;
      out.trips = trips;
      for (int t = 0; t < segments; ++t) {
        const bool inside = t > 0 && t + 1 < segments;
        depth[t] = t == 0 ? sx : inside ? m.depth : sl, index[t] = inside ? ior : 1.0, media[t] = inside ? m.material : -1;
      }
      for (int f = 0; f < k; ++f) material[f] = m.material, normals[f] = face_n, off[f] = f > 0 && f + 1 < k;
      const double p = D > 0.0 ? snell_invariant(depth, index, segments, D, D / std::hypot(D, unfolded), std::min(1.0, ior)) : 0.0;
      double c0 = 0.0, A = 0.0, B = 0.0;
      glm::dvec3 y = x;
      path.k = k;
      bool ok = true;
      for (int t = 0; t < segments && ok; ++t) {
        const double sn = p / index[t], c = std::sqrt(std::max(0.0, 1.0 - sn * sn));
        ok = c > 0.0;
        if (t == 0) c0 = c;
        // towards the face behind (air, then every other segment inside), back towards this one
        const bool inwards = t == 0 || (t + 1 < segments && t % 2 == 1);
        path.d[t] = sn * u + (inwards ? -c : c) * n;
        path.len[t] = depth[t] / c;
        if (t < k) path.y[t] = y = y + path.len[t] * path.d[t];
        A += depth[t] / (index[t] * c);
        B += depth[t] / (index[t] * c * c * c);
        if (trips == 0 && t == 1) r_inside = double(interface_reflectance(mp, float(c), false).x);
      }
      if (!ok) break;
      path.spread = 1.0 / (A * B * c0 * c0);  // A B cos theta_0 with n_L = 1 and cos theta_L = c0
      sink(static_cast<const MirrorPath&>(out), q);
      share *= r_inside * r_inside;
    }
  }
}

void Integrator::connect_laser_mirrors(const NeeVertex& v, double w, const PixelFilm& film, RayCounts* rays) const {
  for_each_mirror_path(glm::dvec3(v.sf.p), laser_.position, &v.sf.p, [&](const MirrorPath& mp, double q) {
    deposit_planar_path(v, mp.path, mp.material, mp.normals, mp.index, mp.media, mp.reflect, w / q, film, &rays->mirror);
  });
}

double Integrator::point_image(const glm::dvec3& d) const {
  const double fp = camera_.focal_length() / camera_.pitch();
  return fp * fp * glm::dot(d, camera_.forward());
}

bool Integrator::camera_mirror_path(const MirrorPath& mp, double intensity, Spec* t, double* opl, int* x, int* y) const {
  const PlanarPath& path = mp.path;
  double px = 0.0, py = 0.0;
  if (!(intensity > 0.0) || !camera_.pixel_of(path.d[0], &px, &py)) return false;
  // every segment meets its face, the last one nothing (a transmissive surface on the way: not rendered)
  FaceHits hits;
  uint64_t rays = 0;
  if (trace_planar_path(glm::vec3(camera_.position()), glm::vec3(path.d[0]), path, mp.material, mp.normals, mp.reflect, nullptr,
                        &rays, hits.f) != PathTrace::Clear)
    return false;
  *t = planar_path_throughput(path, hits.f, mp.index, mp.media, mp.reflect, nullptr, opl);
  *x = int(std::floor(px)), *y = int(std::floor(py));
  return true;
}

void Integrator::find_camera_glints() {
  glints_.clear();
  if (mirrors_.empty() || !laser_traced_) return;
  for_each_mirror_path(camera_.position(), laser_.position, nullptr, [&](const MirrorPath& mp, double) {
    const PlanarPath& path = mp.path;
    const double intensity = laser_.intensity_towards(-path.d[path.k]);
    CameraGlint g;
    Spec t(0.0f);
    if (!camera_mirror_path(mp, intensity, &t, &g.opl, &g.x, &g.y) || !(t.x > 0.0f)) return;
    g.photons = point_image(path.d[0]) * double(t.x) * intensity * path.spread;  // I t spread A cos(theta)
    g.object = mp.trips <= 0 ? mesh_object_[size_t(mirrors_[size_t(mp.mirror)].mesh)] : -1;
    glints_.push_back(g);
  });
}

std::vector<std::pair<int, int>> Integrator::glint_pixels() const {
  std::vector<std::pair<int, int>> out;
  for (const CameraGlint& g : glints_)
    if (std::find(out.begin(), out.end(), std::pair{g.x, g.y}) == out.end()) out.emplace_back(g.x, g.y);
  return out;
}

void Integrator::find_lamps_in_view() {
  lamps_.clear();
  const glm::dvec3 c = camera_.position();
  uint64_t rays = 0;
  for (const PunctualLight& l : ambient_.lights) {
    if (l.type == PunctualLight::Type::Directional) continue;
    // its images in smooth planar faces, as the laser's glints (a lamp in a mirror, and a plate's echoes of it)
    for_each_mirror_path(c, l.position, nullptr, [&](const MirrorPath& mp, double) {
      const PlanarPath& path = mp.path;
      const double intensity = l.intensity_towards(-path.d[path.k]);
      LampInView lamp;
      Spec t(0.0f);
      double opl = 0.0;
      if (!camera_mirror_path(mp, intensity, &t, &opl, &lamp.x, &lamp.y) || !(t.y > 0.0f)) return;
      lamp.photons = point_image(path.d[0]) * double(t.y) * intensity * path.spread;
      lamps_.push_back(lamp);
    });
    const glm::dvec3 to = l.position - c;
    const double r = glm::length(to);
    if (!(r > 0.0)) continue;
    const glm::dvec3 d = to / r;
    const double intensity = l.intensity_towards(-d);
    double px = 0.0, py = 0.0;
    if (!(intensity > 0.0) || !camera_.pixel_of(d, &px, &py)) continue;
    double extra_opl = 0.0;
    const Spec t = shadow_transmittance(glm::vec3(c), glm::vec3(d), float(r), -1, &extra_opl, &rays);
    if (!(t.y > 0.0f)) continue;
    lamps_.push_back({int(std::floor(px)), int(std::floor(py)), point_image(d) * double(t.y) * intensity / (r * r)});
  }
}

// The laser's image in each smooth curved mesh (curved_mirrors_): the path off its surface that obeys the law of
// reflection at the shading normal (solve_planar_path with the mesh's triangles tracked), from the point of the
// mesh whose direction from its centre bisects those of v and the laser (traced inwards; the reflection point of
// a sphere when both are far), on the mesh's front side. One image per mesh: a concave mirror's others are left
// out. No camera path finds it (a Dirac reflection, then the point laser).
void Integrator::connect_laser_curved_mirrors(const NeeVertex& v, double w, const PixelFilm& film, RayCounts* rays) const {
  const glm::dvec3 x(v.sf.p), L = laser_.position;
  for (const CurvedMesh& m : curved_mirrors_) {
    const glm::dvec3 to_x = x - m.centre, to_l = L - m.centre;
    const double rx = glm::length(to_x), rl = glm::length(to_l);
    if (!(rx > m.inner && rl > m.inner)) continue;  // within the sphere of the seed: none sought
    // The seed: the reflection point off the sphere of radius `inner` about the centre (exact for a sphere), on the
    // arc between the directions of v and the laser from the centre, by bisection on the mixture s of the two
    // directions: the normal there bisects the directions to v and the laser. Where that point is within 0.6
    // degrees of grazing either way (v in the sphere's shadow from the laser: none), no image is sought.
    const glm::dvec3 u = to_x / rx, ul = to_l / rl, t = glm::cross(u, ul);
    const auto normal_at = [&](double s) { return glm::normalize((1.0 - s) * u + s * ul); };
    const auto turn = [&](double s) {  // the sine of the angle from the normal to v's direction plus the laser's
      const glm::dvec3 n = normal_at(s), y = m.centre + m.inner * n;
      return glm::dot(glm::cross(n, glm::normalize(x - y)) + glm::cross(n, glm::normalize(L - y)), t);
    };
    double lo = 0.0, hi = 1.0;
    if (glm::dot(u, ul) > -1.0 + 1e-9)
      for (int i = 0; i < 10; ++i) (turn(0.5 * (lo + hi)) > 0.0 ? lo : hi) = 0.5 * (lo + hi);
    const glm::dvec3 b = normal_at(0.5 * (lo + hi)), on = m.centre + m.inner * b;
    if (!(glm::dot(b, glm::normalize(x - on)) > 0.01 && glm::dot(b, glm::normalize(L - on)) > 0.01)) continue;
    const double reach = 2.0 * m.radius + 1e-3;
    ++rays->mirror;
    RayHit hit;
    if (!embree_.intersect(glm::vec3(m.centre + reach * b), glm::vec3(-b), 0.0f, float(reach), &hit) || hit.mesh != m.mesh) continue;
    PlanarFace face;
    if (!shading_.face(hit.mesh, hit.triangle, &face) || !face.shaded) continue;
    const glm::dvec3 start = m.centre + reach * b - double(hit.t) * b;
    const double index[2] = {1.0, 1.0};
    const int media[2] = {-1, -1};
    const bool off[1] = {true}, shaded[1] = {true};
    const MeshTracker tracker(embree_, shading_, v.sf.ng, &rays->mirror, false);
    PlanarPath path;
    if (!solve_planar_path(x, L, &face, index, 1, &start, &path, off, &tracker)) continue;
    // (on its front side: the outside of a closed mesh)
    if (!(glm::dot(x - path.y[0], path.n[0]) > 0.0 && glm::dot(L - path.y[0], path.n[0]) > 0.0)) continue;
    const glm::vec3 ng(path.n[0]);
    deposit_planar_path(v, path, &m.material, &ng, index, media, off, w, film, &rays->mirror, shaded);
  }
}

// The laser's light refracted through each smooth glass mesh of curved_refractors_ (a glass sphere) to v, along
// every path the search finds, in and out of the mesh alone. The search (render/sphere_search.h): in the plane of
// the laser, the mesh's bounding-box centre and v (where every path through a sphere lies; the plane turns about
// the axis from the laser through the centre), the rays from the laser through the sphere of radius `inner` about
// that centre whose exit passes through v, each the seed of a solve on the mesh's triangles (solve_planar_path,
// the triangles tracked as connect_laser_shaded's). Beyond a sphere's focus its light reaches a point on the other
// side of its axis, and around the focus along up to three paths: a walk from the straight line to the laser finds
// at most one of them, and none where that line misses the mesh. Entry or exit within 0.6 degrees of grazing is
// left out (a transmittance below 0.04 at ior 1.5).
void Integrator::connect_laser_curved_refractors(const NeeVertex& v, double w, const PixelFilm& film, RayCounts* rays) const {
  const glm::dvec3 x(v.sf.p), L = laser_.position;
  for (const CurvedMesh& m : curved_refractors_) {
    const glm::dvec3 to_l = m.centre - L;
    const double dl = glm::length(to_l);
    if (!curved_refractor_searched(m, x)) continue;
    // The plane's axes: a from the laser through the centre, b towards v's side of it.
    const glm::dvec3 a = to_l / dl, rel = x - m.centre;
    const double xa = glm::dot(rel, a);
    glm::dvec3 b = rel - xa * a, b_any(0.0), c_any(0.0);
    const double xb = glm::length(b);
    make_basis(a, &b_any, &c_any);
    b = xb > 1e-12 * (1.0 + glm::length(rel)) ? b / xb : b_any;
    const glm::dvec2 X(xa, xb);
    const double n = medium_ior(m.material);
    glm::dvec3 found[kMaxCurvedRefractorPaths];
    int n_found = 0;
    for (const SphereSearch& search : m.searches) {
      if (!(glm::length(rel) > search.radius() && dl > search.radius())) continue;
      SphereRay seeds[kMaxCurvedRefractorSeeds];
      const int n_seeds = search.seeds(X, seeds, kMaxCurvedRefractorSeeds);
      for (int i = 0; i < n_seeds && n_found < kMaxCurvedRefractorPaths; ++i) {
        const SphereRay& root = seeds[i];
        // The seed's triangles: the exit's seen from v, the entry's from the laser.
        const glm::dvec3 exit3 = m.centre + root.exit.x * a + root.exit.y * b, entry3 = m.centre + root.entry.x * a + root.entry.y * b;
        PlanarFace faces[2];
        glm::dvec3 start[2];
        const glm::vec3 origin = offset_ray_origin(v.sf.p, v.sf.ng, glm::vec3(exit3 - x));
        const glm::dvec3 to_exit = glm::normalize(exit3 - glm::dvec3(origin)), to_entry = glm::normalize(entry3 - L);
        RayHit hit;
        rays->refracted += 2;
        if (!embree_.intersect(origin, glm::vec3(to_exit), 0.0f, std::numeric_limits<float>::infinity(), &hit, true) ||
            hit.mesh != m.mesh || !shading_.face(hit.mesh, hit.triangle, &faces[0]))
          continue;
        start[0] = glm::dvec3(origin) + double(hit.t) * to_exit;
        if (!embree_.intersect(glm::vec3(L), glm::vec3(to_entry), 0.0f, std::numeric_limits<float>::infinity(), &hit, false) ||
            hit.mesh != m.mesh || !shading_.face(hit.mesh, hit.triangle, &faces[1]))
          continue;
        start[1] = L + double(hit.t) * to_entry;
        const double index[3] = {1.0, n, 1.0};
        const int media[3] = {-1, m.material, -1}, material[2] = {m.material, m.material};
        const bool shaded[2] = {true, true};
        const MeshTracker tracker(embree_, shading_, v.sf.ng, &rays->refracted, true);
        PlanarPath path;
        if (!solve_planar_path(x, L, faces, index, 2, start, &path, nullptr, &tracker)) continue;
        // (two seeds that reached the same path)
        const double tol = 1e-6 * (1.0 + glm::length(path.y[0]));
        if (std::any_of(found, found + n_found, [&](const glm::dvec3& y) { return glm::length(y - path.y[0]) <= tol; })) continue;
        found[n_found++] = path.y[0];
        const glm::vec3 ng[2] = {glm::vec3(path.n[0]), glm::vec3(path.n[1])};
        (void)deposit_planar_path(v, path, material, ng, index, media, nullptr, w, film, &rays->refracted, shaded);
      }
    }
  }
}

bool Integrator::curved_refractor_searched(const CurvedMesh& m, const glm::dvec3& x) const {
  const double R = m.inner;
  return R > 0.0 && glm::length(m.centre - laser_.position) > R && glm::length(x - m.centre) > R;
}

bool Integrator::through_curved_refractor_alone(const Crossings& cx, const glm::dvec3& x) const {
  const Crossings::Crossing* cr = cx.slots.c;
  if (!(cx.n == 2 && cx.medium0 < 0 && cr[0].mesh == cr[1].mesh && cr[1].medium < 0 && cr[0].medium == cr[0].material)) return false;
  return std::any_of(curved_refractors_.begin(), curved_refractors_.end(),
                     [&](const CurvedMesh& m) { return m.mesh == cr[0].mesh && curved_refractor_searched(m, x); });
}

inline void Integrator::connect_laser(const NeeVertex& v, const LaserRay& lr, const FirstSegment* first, double w,
                                      const PixelFilm& film, RayCounts* rays) const {
  if (!mirrors_.empty() && v.medium < 0) connect_laser_mirrors(v, w, film, rays);
  if (!curved_mirrors_.empty() && v.medium < 0) connect_laser_curved_mirrors(v, w, film, rays);
  if (!curved_refractors_.empty() && v.medium < 0) connect_laser_curved_refractors(v, w, film, rays);
  const double r = lr.r, intensity = lr.intensity;
  const glm::vec3 wi = lr.wi;
  // With refracting volumes the straight walk comes first: it finds the interfaces that the refracted
  // connection crosses, and its transmittance is the straight connection's.
  Spec tr(0.0f);
  double extra = 0.0;
  if (refractive_) {
    Crossings cx;
    tr = shadow_transmittance(lr.origin, wi, float(r), v.shadow_medium_towards(wi), &extra, &rays->laser, first, &cx);
    if (edges_ && v.medium >= 0) connect_laser_edges(v, lr, cx, w, film, rays);
    if (!rough_slabs_.empty() && v.medium < 0) connect_laser_rough_slabs(v, cx, w, film, rays);
    if (cx.blocked) return;
    if (cx.refracting && cx.planar && rough_crossings(cx)) {
      connect_laser_rough(v, cx, w, film, rays);
      return;
    }
    if (cx.refracting && cx.planar &&
        (cx.parallel ? connect_laser_refracted(v, lr, cx, w, film, rays, true) : connect_laser_planar(v, cx, w, film, rays, true)))
      return;
    if (cx.refracting && !cx.planar && cx.complete) {
      // (through one glass mesh alone: connect_laser_curved_refractors' paths)
      if (!(v.medium < 0 && through_curved_refractor_alone(cx, glm::dvec3(v.sf.p)))) connect_laser_shaded(v, cx, w, film, rays);
      return;
    }
  }
  if (!(intensity > 0.0) || !v.counted(wi)) return;  // (outside the beam: the images' connections above alone)
  const Spec f = v.bsdf.eval_cos(wi);
  if (!(f.x > 0.0f)) return;
  if (!refractive_)
    tr = shadow_transmittance(lr.origin, wi, float(r), v.shadow_medium_towards(wi), &extra, &rays->laser, first);
  if (!(tr.x > 0.0f)) return;
  const double value = double(v.beta.x) * f.x * tr.x * intensity / (r * r) * w;
  deposit_laser(v, value, v.opl + r + extra, film);
}

// The light entering through an edge: the edge's plane is the one interface, at the edge's middle; the
// refracted path connect_laser_refracted solves and traces must meet the edge itself (else the plate's
// face: no such path from v). Only edges whose refracted light can climb from the edge to v's face within
// the plate (twice its thickness, for the spread of the laser's direction along the edge) are tried.
void Integrator::connect_laser_edges(const NeeVertex& v, const LaserRay& lr, const Crossings& cx, double w,
                                     const PixelFilm& film, RayCounts* rays) const {
  const glm::dvec3 x(v.sf.p);
  for (const GlossyStrip& st : strips_) {
    if (st.slab < 0) continue;
    const GlossySlab& s = slabs_[size_t(st.slab)];
    if (v.medium != s.material || st.offset - glm::dot(st.out, x) > 2.0 * st.per_reflection) continue;
    EdgeEntry en;
    // (v on the edge: the straight walk's)
    if (!edge_entry(x, s, st, &en) || !(en.hg > 1e-3 * (s.hi - s.lo)) || en.climb > 2.0) continue;
    const glm::dvec3 &c = en.c, &e = st.out;
    // The straight walk's path when it left through this edge.
    if (cx.n > 0 && cx.slots.c[0].material == s.material && std::fabs(glm::dot(glm::dvec3(cx.slots.c[0].ng), e)) > 1.0 - 1e-6 &&
        std::fabs(glm::dot(cx.slots.c[0].p - c, e)) <= 1e-6 * (1.0 + glm::length(st.a)))
      continue;
    Crossings ex;
    ex.n = 1;
    ex.medium0 = s.material;
    ex.refracting = true;
    Crossings::Crossing& cr = ex.slots.c[0];
    cr.p = c;
    cr.ng = glm::vec3(e);
    cr.material = s.material;
    cr.mp = strip_material(st, c);
    cr.medium = -1;
    connect_laser_refracted(v, lr, ex, w, film, rays, false, std::sqrt(std::max(0.0, 1.0 - en.ce * en.ce)));  // its angle there
  }
}

// The material at point c of strip st (on its plane): the base colour's texture and COLOR_0 at c, from c's
// barycentrics in whichever of the strip's two triangles holds it (the nearer one when rounding puts it
// outside both).
MaterialPoint Integrator::strip_material(const GlossyStrip& st, const glm::dvec3& c) const {
  RayHit hit;
  double best = std::numeric_limits<double>::infinity();
  for (int i = 0; i < 2; ++i) {
    const GlossyPart& g = parts_[st.part[i]];
    const glm::dvec3 d = c - g.p0;
    const double e11 = glm::dot(g.e1, g.e1), e12 = glm::dot(g.e1, g.e2), e22 = glm::dot(g.e2, g.e2);
    const double d1 = glm::dot(d, g.e1), d2 = glm::dot(d, g.e2), den = e11 * e22 - e12 * e12;
    const double u = (e22 * d1 - e12 * d2) / den, v = (e11 * d2 - e12 * d1) / den;
    const double outside = std::max({0.0, -u, -v, u + v - 1.0});
    if (!(outside < best)) continue;
    best = outside;
    const double uc = std::clamp(u, 0.0, 1.0), vc = std::clamp(v, 0.0, 1.0 - uc);
    hit.mesh = uint32_t(st.mesh), hit.triangle = st.triangle[i], hit.u = float(uc), hit.v = float(vc);
  }
  Surface sf;
  sf.mesh = st.mesh;
  sf.material = slabs_[size_t(st.slab)].material;
  return shading_.material_at(sf, hit);
}

// Without an ambient source (ambient_on_ false) a laser-only render skips the ambient sums altogether.
inline void Integrator::gather_environment(const Spec& beta, double* ambient) const {
  if (ambient_on_) *ambient += double(beta.y) * ambient_.environment_radiance;
}

inline void Integrator::gather_emission(const Spec& beta, const MaterialPoint& mp, double* ambient) const {
  if (ambient_on_ && mp.emission.y > 0.0f) *ambient += double(beta.y) * mp.emission.y;
}

inline void Integrator::connect_ambient_lights(const NeeVertex& v, double* ambient, RayCounts* rays) const {
  for (const PunctualLight& l : ambient_.lights) {
    glm::dvec3 wid;
    double r, e;
    if (l.type == PunctualLight::Type::Directional) {
      wid = -l.direction;
      r = std::numeric_limits<double>::infinity();
      e = l.power;
    } else {
      const glm::dvec3 to = l.position - glm::dvec3(v.sf.p);
      // A light in the surface's plane, to within the hit point's rounding, lights it at grazing
      // incidence (none of its light), where cos / r^2 would read that rounding as a height: a light in a
      // lit plane put 2.7e6 photons/s in the pixel it sits in, instead of 0.
      const double p_max = std::max({std::fabs(double(v.sf.p.x)), std::fabs(double(v.sf.p.y)), std::fabs(double(v.sf.p.z))});
      if (std::fabs(glm::dot(to, glm::dvec3(v.sf.ng))) <= kPlaneRoundingUlps * double(FLT_EPSILON) * p_max) continue;
      r = glm::length(to);
      wid = to / r;
      e = l.intensity_towards(-wid) / (r * r);
    }
    if (!(e > 0.0) || !v.counted(glm::vec3(wid))) continue;
    const glm::vec3 wi(wid);
    const Spec f = v.bsdf.eval_cos(wi);
    if (!(f.y > 0.0f)) continue;
    double extra = 0.0;
    const Spec tr = shadow_transmittance(offset_ray_origin(v.sf.p, v.sf.ng, wi), wi, float(r),
                                         v.shadow_medium_towards(wi), &extra, &rays->ambient);
    *ambient += double(v.beta.y) * f.y * tr.y * e;
  }
}

// The guided connections' targets from a glossy vertex: where its mirror reflection and its refraction
// (the directions its narrow lobes scatter around) first meet a glossy surface of narrow lobe that can
// reflect the laser back towards the vertex. Each target's laser direction is the straight one, refracted
// into the medium the vertex's side of the surface is in (a plate's parallel faces); its alpha is the
// surface's, narrowed by 1 + r_vertex / r_laser, because moving along the surface turns the half-vector
// by the laser's parallax as well. Every choice here depends on the vertex only, so the targets' densities
// are exact whatever they are: they set how well the guided draws fit, never what they estimate.
void Integrator::find_guide_targets(const Surface& sf, const Bsdf& bsdf, int medium_r, int medium_t,
                                    GuideTargets* out, RayCounts* rays) const {
  out->n = 0;
  out->origin = glm::dvec3(sf.p);
  if (bsdf.lambertian()) {
    lambertian_guide_targets(sf, out);
    return;
  }
  if (!bsdf.glossy()) return;
  glm::vec3 dirs[2];
  int media[2], n = 0;
  dirs[n] = bsdf.mirror_direction(), media[n++] = medium_r;
  if (bsdf.refracted_direction(&dirs[n])) media[n++] = medium_t;
  for (int i = 0; i < n; ++i) {
    const glm::vec3 d = dirs[i];
    RayHit hit;
    ++rays->guided;
    if (!embree_.intersect(offset_ray_origin(sf.p, sf.ng, d), d, 0.0f, kInf, &hit)) continue;
    const Surface sb = shading_.geometric(hit);
    const MaterialPoint& mb = shading_.material(sb.material).point;
    if (mb.lambertian || mb.smooth() || mb.alpha > kGuideMaxAlpha) continue;
    const glm::vec3 nb = glm::dot(sb.ng, d) > 0.0f ? -sb.ng : sb.ng;
    const glm::dvec3 to = laser_.position - glm::dvec3(sb.p);
    const double r_laser = glm::length(to);
    if (!(r_laser > 0.0)) continue;
    glm::vec3 wl(to / r_laser);
    if (!(laser_.intensity_towards(-glm::dvec3(wl)) > 0.0)) continue;
    if (media[i] >= 0) {  // seen from inside a medium: refracted at the surface's plane
      const float eta = shading_.material(media[i]).point.ior;
      const float c = glm::dot(wl, nb);
      const glm::vec3 t = (wl - c * nb) / eta;
      const float t2 = glm::dot(t, t);
      if (!(t2 < 1.0f)) continue;
      wl = glm::normalize(t + std::copysign(std::sqrt(1.0f - t2), c) * nb);
    }
    const double r_vertex = glm::length(glm::dvec3(sb.p) - glm::dvec3(sf.p));
    const float alpha = float(double(mb.alpha) / (1.0 + r_vertex / r_laser));
    if (glm::dot(wl, nb) > 0.0f) {  // else the laser is behind the surface: no reflection of it
      GuideTarget& g = out->t[out->n++];
      g.lobe = GlossyTarget{nb, wl, alpha};
    }
    // b inside a plate: also its reflection of the light entering through the plate's edges (the laser
    // connection at b takes that path too, connect_laser_edges).
    if (!edges_ || media[i] < 0) continue;
    for (const GlossyStrip& st : strips_) {
      if (out->n == kMaxGuideTargets) break;
      if (st.slab < 0 || slabs_[size_t(st.slab)].material != media[i] ||
          st.offset - glm::dot(st.out, glm::dvec3(sb.p)) > 2.0 * st.per_reflection)
        continue;
      const GlossySlab& s = slabs_[size_t(st.slab)];
      const double zb = glm::dot(glm::dvec3(sb.p), s.n), tol = 1e-6 * std::max(1.0, std::fabs(zb));
      const bool on_lo = std::fabs(zb - s.lo) <= tol;
      if (!on_lo && !(std::fabs(zb - s.hi) <= tol)) continue;
      EdgeEntry en;  // the edge's light reaches b only after reflections:
      if (!edge_entry(glm::dvec3(sb.p), s, st, &en) || en.climb >= 2.0) continue;
      glm::dvec3 we;
      if (!edge_path(glm::dvec3(sb.p), s, st, on_lo, 0, alpha, &we) || !(glm::dot(glm::vec3(we), nb) > 0.0f)) continue;
      GuideTarget& ge = out->t[out->n++];
      ge.lobe = GlossyTarget{nb, glm::vec3(we), alpha};
    }
  }
}

// A Lambertian vertex in air aims at the glossy plates' parts that can mirror the laser towards it
// (both on the same side of the part's plane): at a part's glossy reflection of the laser where the
// mirror point (where the line to the laser's image behind the plane meets it) lies on the part or
// within kGuideEdgeWidths of the lobe's widths of it (one target per plane: a face of two triangles
// aims once; a sliver's two triangles not at all); and along a sliver (a plate's 2 mm edge, which the
// vertex's BSDF draws rarely hit) whose mirror point is beside it, when the half-vector at the sliver's
// point nearest the mirror point is within 25 degrees of its normal: the lobe's tail there outshines the
// rest. The half-vector's slope m is nearly linear
// along the sliver, so GGX's D ~ 1 / (alpha^2 + |m|^2)^2 falls along it as 1 / (1 + ((s - s*) / c)^2)^2,
// about the s* of least |m| (which moves with t across the sliver), of c = sqrt(alpha^2 + m*^2) / |dm/ds|:
// s is drawn from a Cauchy law of that scale (the integrand over the density stays bounded). At grazing
// incidence, as on a plate's 2 mm edge, |dm/ds| is 1 / cos(theta) times its value at normal incidence:
// a glint of 0.1 mm. No ray is traced to choose: the targets depend on the vertex alone.
void Integrator::lambertian_guide_targets(const Surface& sf, GuideTargets* out) const {
  const glm::dvec3 x(sf.p), L = laser_.position;
  int aimed[kMaxGuideTargets];  // the planes aimed at
  int planes = 0;
  for (const GlossyPart& part : parts_) {
    if (out->n == kMaxGuideTargets) return;
    if (part.sliver) continue;
    const double hx = glm::dot(x - part.p0, part.n), hl = glm::dot(L - part.p0, part.n);
    if (!(hx * hl > 0.0)) continue;
    const glm::dvec3 q = x + (hx / (hx + hl)) * (L - 2.0 * hl * part.n - x);
    const double r_vertex = glm::length(q - x), r_laser = glm::length(L - q);
    if (!(r_vertex > 0.0 && r_laser > 0.0)) continue;
    // One target per plane (a face of several triangles): the lobe depends on the plane alone.
    if (std::find(aimed, aimed + planes, part.plane) != aimed + planes) continue;
    const double k = 0.5 * (1.0 / r_vertex + 1.0 / r_laser);
    if (distance_to_triangle(q, part.p0, part.e1, part.e2) > kGuideEdgeWidths * double(part.alpha) / k) continue;
    const glm::dvec3 wl = (L - q) / r_laser;
    if (!(laser_.intensity_towards(-wl) > 0.0)) continue;
    aimed[planes++] = part.plane;
    GuideTarget& g = out->t[out->n++];
    g.strip = false;
    g.lobe = GlossyTarget{glm::vec3(hx > 0.0 ? part.n : -part.n), glm::vec3(wl),
                          float(double(part.alpha) / (1.0 + r_vertex / r_laser))};
  }
  for (const GlossyStrip& strip : strips_) {
    if (out->n == kMaxGuideTargets) return;
    const double hx = glm::dot(x - strip.o, strip.n), hl = glm::dot(L - strip.o, strip.n);
    if (!(hx * hl > 0.0)) continue;
    const glm::dvec3 nb = hx > 0.0 ? strip.n : -strip.n;
    const glm::dvec3 q = x + (hx / (hx + hl)) * (L - 2.0 * hl * strip.n - x);
    const glm::dvec2 st = strip_coordinates(q, strip.o, strip.a, strip.b);
    const double s0 = std::clamp(st.x, 0.0, 1.0);
    const glm::dvec3 near = strip.o + s0 * strip.a + std::clamp(st.y, 0.0, 1.0) * strip.b;
    const double r_vertex = glm::length(near - x), r_laser = glm::length(L - near);
    if (!(r_vertex > 0.0 && r_laser > 0.0)) continue;
    const glm::dvec3 wl = (L - near) / r_laser;
    const double ch = glm::dot(glm::normalize(wl + (x - near) / r_vertex), nb);
    if (!(laser_.intensity_towards(-wl) > 0.0)) continue;
    // The half-vector's slope m (its part along the sliver over its part along nb) at the nearest point,
    // and its derivatives along s and t: u = wl + wv moves by -(dp - (dp . w) w) / r for each of w.
    const glm::dvec3 wv = (x - near) / r_vertex, h = wl + wv;
    const double hn = glm::dot(h, nb);
    const glm::dvec3 m0 = (h - hn * nb) / hn;
    const auto slope_rate = [&](const glm::dvec3& dp) {
      const glm::dvec3 dh = -(dp - glm::dot(dp, wl) * wl) / r_laser - (dp - glm::dot(dp, wv) * wv) / r_vertex;
      const double dhn = glm::dot(dh, nb);
      return ((dh - dhn * nb) * hn - (h - hn * nb) * dhn) / (hn * hn);
    };
    const glm::dvec3 A = slope_rate(strip.a), B = slope_rate(strip.b);
    const double a2 = glm::dot(A, A);
    if (!(a2 > 0.0)) continue;
    // Linear in (s, t) about the nearest point (s_n, t_n), |m| is least along s at
    // s*(t) = s_n - (m0 + (t - t_n) B) . A / |A|^2, where it is |m0 + (s* - s_n) A + (t - t_n) B|.
    const double t_n = std::clamp(st.y, 0.0, 1.0);
    const double shift = -glm::dot(m0, A) / a2, per_t = -glm::dot(B, A) / a2;
    // Along that line, m = m_s + (t - t_n) C: least over the sliver's width at t*. Seen at grazing
    // incidence, the half-vector turns by tens of degrees across the 2 mm width, so the point nearest the
    // mirror point can be far from the glint while the other side of the sliver holds it.
    const glm::dvec3 m_s = m0 + shift * A, C = B + per_t * A;
    const double c2 = glm::dot(C, C);
    const double t_best = c2 > 0.0 ? std::clamp(t_n - glm::dot(m_s, C) / c2, 0.0, 1.0) : t_n;
    const double m_least = glm::length(m_s + (t_best - t_n) * C);
    if (ch < kGuideMaxTilt && !(m_least <= kGuideMaxSlope)) continue;
    GuideTarget& g = out->t[out->n++];
    g.strip = true;
    g.part = &strip;
    g.s0 = s0 + shift - t_n * per_t;
    g.s1 = per_t;
    g.c = std::sqrt(double(strip.alpha) * double(strip.alpha) + m_least * m_least) / std::sqrt(a2);
  }
}

// The guided strategies at a glossy vertex a: for each target, a direction drawn towards its reflection
// of the laser, traced to the next vertex b, and the laser's connection from b, weighted against a's own
// BSDF draw by the power heuristic (Veach's beta = 2: where one strategy's density is far above the
// other's, as a plate's narrow transmission lobe is above the guided draw's, its weight is ~1 and the
// other adds next to no noise; the balance heuristic measured 1.3 times the variance there). The BSDF
// draw picks one lobe L and survives Russian roulette with probability q_L, so the integrand's part
// through lobe L has the strategies {lobe L (density p_L = pdf_L q_L), the targets i (pdf_i)}: a draw w
// from target i adds sum_L f_cos_L(w) pdf_i(w) / (p_L(w)^2 + sum_k pdf_k(w)^2) times what the laser
// returns through b, and the BSDF draw's connection at b is weighted p_L^2 / (p_L^2 + sum_k pdf_k^2)
// (trace_path's next_mis).
void Integrator::guided_connections(const NeeVertex& a, int medium_t, bool roulette, const Spec& rr_beta,
                                    const GuideTargets& guide, Rng& rng, double w, const PixelFilm& film,
                                    RayCounts* rays, const Ghosts* ghosts) const {
  for (int i = 0; i < guide.n; ++i) {
    const float u = uniform(rng), v = uniform(rng);
    glm::vec3 wd;
    if (!guide.sample(i, u, v, &wd)) continue;
    const LobeValues lv = a.bsdf.lobes(wd);
    const double pi = guide.pdf(i, wd);
    if (!(pi > 0.0)) continue;
    double pg2 = guide.sum_pdf2(wd);
    if (ghosts != nullptr && (glm::dot(wd, a.sf.ng) > 0.0f) == a.wo_front) pg2 += ghosts->sum_pdf2(wd, 1);
    Spec f(0.0f);
    for (int l = 0; l < kLobes; ++l) {
      if (!(lv.f_cos[l].x > 0.0f)) continue;
      double p = lv.pdf[l];
      if (roulette && p > 0.0)
        p *= roulette_q(rr_beta * lv.f_cos[l] * (l == kTransmissionLobe ? a.bsdf.eta() * a.bsdf.eta() : 1.0f) / lv.pdf[l]);
      f += lv.f_cos[l] * float(pi / (p * p + pg2));
    }
    if (!(f.x > 0.0f)) continue;
    RayHit hit;
    ++rays->guided;
    if (!embree_.intersect(offset_ray_origin(a.sf.p, a.sf.ng, wd), wd, 0.0f, kInf, &hit)) continue;
    const Surface sb = shading_.surface(hit);
    const MaterialPoint mb = shading_.material_at(sb, hit);
    const auto [wo_front, bsdf, volume] = shade(sb, mb, wd);
    if (!bsdf.has_non_delta()) continue;
    const bool transmitted = (glm::dot(wd, a.sf.ng) > 0.0f) != a.wo_front;
    const int medium = transmitted ? medium_t : a.medium;
    const double seg = glm::length(glm::dvec3(sb.p) - glm::dvec3(a.sf.p));
    Spec beta = a.beta * f;
    double opl = a.opl + seg;
    if (medium >= 0) {
      const ResolvedMaterial& rm = shading_.material(medium);
      if (rm.absorbing) beta *= glm::exp(-rm.sigma * static_cast<float>(seg));
      opl += (double(rm.point.ior) - 1.0) * seg;
    }
    if (!(beta.x > 0.0f)) continue;
    // b is a's next vertex: a is a non-delta vertex before it.
    const NeeVertex vb{sb, bsdf, wo_front, volume, medium, a.vertices + 1, a.seen_through && transmitted, beta, opl,
                       !(mb.transmission > 0.0f)};
    LaserRay lr;
    RayCounts at_end;  // the laser connection at the guided vertex: the guided connection's rays
    if (laser_ray(sb, &lr)) connect_laser(vb, lr, nullptr, w, film, &at_end);
    rays->guided += at_end.total();
  }
}

// The ghost of the laser a non-delta vertex x in air sees through a glossy plate: the light that enters the
// plate's far face, reflects inside off its near face, then off its far face, and leaves through the near
// face towards x (or the reverse). Unfolded, it is a straight refracted path through three times the
// plate's thickness, whose Snell invariant p solves rho(p) = (h_x + h_L) tan(theta) + 3 d tan(theta_glass)
// = D (the lateral offset), as in connect_laser_refracted. A camera path meets that light only through
// three narrow lobes (the transmission into the plate, then the two reflections: the last one evaluated by
// the laser connection), which the BSDF's draws at x find rarely (and x's own lobe, if narrow, more rarely
// still); the ghost's target is a GGX lobe of directions about the ghost's direction at x, of alpha
// 2 sqrt(2) n alpha_plate / (1 + r_x / r_L) (two reflections each turning the ray by twice its
// microfacet's tilt, n times wider outside, and the parallax of moving along the plate as for the guided
// targets). From a vertex inside the plate, on its face away from the laser (the plate's own back face:
// its diffuse lobe, or its glossy reflection of a camera ray that entered the plate), the ghost is two
// reflections away: the unfolded path starts in the glass, and the lobe, in the glass, has alpha
// 2 sqrt(2) alpha_plate. The higher orders the same way, m reflections turning the lobe sqrt(m) times
// wider: the second-order ghost (four reflections, five thicknesses unfolded) from the air behind the
// plate and from its far face inside; from its face towards the laser inside, the ghost of three
// reflections (off the far face, the near face, the far face: four thicknesses unfolded). A vertex inside
// the plate on either face also aims at the light entering through the plate's edges
// (edge_ghost_targets). As for the guided targets, the choice depends on x alone, so the densities are
// exact whatever it is.
void Integrator::ghost_targets(const Surface& sf, int medium, Ghosts* out) const {
  out->n = 0;
  const glm::dvec3 x(sf.p), L = laser_.position;
  for (const GlossySlab& s : slabs_) {
    const double sx = glm::dot(x, s.n), sl = glm::dot(L, s.n), d = s.hi - s.lo;
    // Where x is: in the air behind the plate (the laser beyond its far face), or inside it on its face
    // away from the laser (far) or towards it (near).
    bool up, down, near_face = false;
    double hx;  // the path's length in air along the normal before it enters the plate
    if (medium < 0) {
      up = sx < s.lo && sl > s.hi, down = sx > s.hi && sl < s.lo;
      hx = up ? s.lo - sx : sx - s.hi;
    } else {
      if (medium != s.material) continue;
      const double tol = 1e-6 * std::max(1.0, std::fabs(sx));
      const bool on_lo = std::fabs(sx - s.lo) <= tol, on_hi = std::fabs(sx - s.hi) <= tol;
      if (on_lo || on_hi) edge_ghost_targets(x, s, int(&s - slabs_.data()), on_lo, out);
      up = on_lo && sl > s.hi, down = on_hi && sl < s.lo;
      if (!up && !down && ((on_hi && sl > s.hi) || (on_lo && sl < s.lo))) {
        near_face = true;
        up = on_hi;  // the laser beyond the face x is on
        down = on_lo;
      }
      hx = 0.0;
    }
    if (!up && !down) continue;
    const glm::dvec3 nrm = up ? s.n : -s.n;  // towards the laser
    const double hl = near_face ? std::fabs(sl - sx) : std::fabs(sl - sx) - hx - d;
    const glm::dvec3 to = L - x;
    const glm::dvec3 lat = to - glm::dot(to, nrm) * nrm;
    const double D = glm::length(lat);
    const glm::dvec3 u = D > 0.0 ? lat / D : glm::dvec3(0.0);
    const double n = s.ior;
    // The orders drawn: the glass the unfolded path crosses (in thicknesses), its reflections inside, the
    // vertices from x to the one whose laser connection meets it (reach), the share of vertices that draw.
    struct Order {
      double glass;
      int reflections, reach;
      float share;
    };
    static constexpr Order kFar[2] = {{3.0, 2, 2, float(kGhostDrawShare)}, {5.0, 4, 4, kSecondGhostDrawShare}};
    static constexpr Order kAir[2] = {{3.0, 2, 3, float(kGhostDrawShare)}, {5.0, 4, 5, kSecondGhostDrawShare}};
    static constexpr Order kNear[1] = {{4.0, 3, 3, kSecondGhostDrawShare}};
    const Order* orders = near_face ? kNear : medium < 0 ? kAir : kFar;
    const int count = near_face ? 1 : 2;
    double p = -1.0;
    for (int o = 0; o < count && out->n < Ghosts::kMax; ++o) {
      const Order& od = orders[o];
      const double depth[2] = {hx + hl, od.glass * d}, index[2] = {1.0, n};
      const double guess = p >= 0.0 ? p : std::min(D / glm::length(to), 0.5);
      p = D > 0.0 ? snell_invariant(depth, index, 2, D, guess, 1.0) : 0.0;
      const double ca = std::sqrt(std::max(0.0, 1.0 - p * p));
      if (!(ca > 0.0)) break;
      const glm::dvec3 wl = p * u + ca * nrm;  // in air, towards the laser
      if (!(laser_.intensity_towards(-wl) > 0.0)) continue;
      const double sg = p / n, cg = std::sqrt(1.0 - sg * sg);
      // x's direction: in air the ghost's; inside, into the glass (towards the laser from the far face,
      // away from it from the near face)
      const glm::dvec3 w0 = medium < 0 ? wl : sg * u + (near_face ? -cg : cg) * nrm;
      const double rx = hx / ca, rl = hl / ca;
      // each reflection turns the ray by twice its microfacet's tilt; outside, n times wider and narrowed by
      // the parallax of moving along the plate, as for the guided targets
      const double alpha = std::clamp(2.0 * std::sqrt(double(od.reflections)) * (medium < 0 ? n : 1.0) * double(s.alpha) /
                                          (1.0 + rx / std::max(rl, 1e-9)),
                                      1e-3, 0.5);
      if (medium < 0) {
        // The entry point must lie on one of the plate's faces in the near plane, or within the lobe's
        // reach of one.
        const double entry_plane = up ? s.lo : s.hi;
        const glm::dvec3 q = x + rx * w0;
        bool on = false;
        for (const GlossyPart& part : parts_) {
          const double off = std::fabs(glm::dot(part.p0, s.n) - entry_plane);
          if (std::fabs(glm::dot(part.n, s.n)) < 1.0 - 1e-6 || off > 1e-6 + 1e-9 * std::fabs(entry_plane)) continue;
          if ((on = distance_to_triangle(q, part.p0, part.e1, part.e2) <= kGuideEdgeWidths * alpha * rx)) break;
        }
        if (!on) continue;
      }
      out->reach[out->n] = od.reach;
      out->share[out->n] = od.share;
      out->lobe[out->n++] = DirectionLobe{glm::vec3(w0), float(alpha)};
    }
  }
}

// The laser's light that enters a plate through one of its edges (a GlossyStrip across the plate's
// thickness, lit by the laser) and is reflected k times between the plate's faces (totally, beyond the
// critical angle) before it reaches x, a vertex inside the plate on one of its faces: a light pipe that
// x's own lobes (a plate's diffuse lobe) meet only in a narrow cone of directions, whose light the laser
// connection at the k-th vertex on returns through the edge (connect_laser_edges). For each k (reach k,
// from 1 to kMaxGhostReach) about edge_entry's estimate whose path edge_path finds: a lobe about its
// direction at x of alpha 2 sqrt(k) alpha_plate (k reflections, each turning the ray by twice its
// microfacet's tilt). Reach 1 is the next vertex's laser connection, which the guided connections aim at
// too: trace_path weighs the two together.
void Integrator::edge_ghost_targets(const glm::dvec3& x, const GlossySlab& s, int slab, bool on_lo,
                                    Ghosts* out) const {
  for (const GlossyStrip& st : strips_) {
    if (st.slab != slab || st.offset - glm::dot(st.out, x) > (kMaxGhostReach + 2) * st.per_reflection) continue;
    EdgeEntry en;
    if (!edge_entry(x, s, st, &en)) continue;
    const int k_est = int(std::floor(en.climb));
    for (int k = std::max(1, k_est - 1); k <= std::min(kMaxGhostReach, k_est + 1) && out->n < Ghosts::kMax; ++k) {
      const double alpha = std::clamp(2.0 * std::sqrt(double(k)) * double(s.alpha), 1e-3, 0.5);
      glm::dvec3 w;
      if (!edge_path(x, s, st, on_lo, k, alpha, &w)) continue;
      out->reach[out->n] = k;
      out->share[out->n] = kEdgeGhostDrawShare;
      out->lobe[out->n++] = DirectionLobe{glm::vec3(w), float(alpha)};
    }
  }
}

bool Integrator::edge_entry(const glm::dvec3& x, const GlossySlab& s, const GlossyStrip& st, EdgeEntry* out) const {
  const glm::dvec3 L = laser_.position;
  const double len = glm::length(st.a);
  const glm::dvec3 along = st.a / len;
  out->c = st.o + std::clamp(glm::dot(x - st.o, along), 0.0, len) * along + 0.5 * st.b;
  out->hg = glm::dot(out->c - x, st.out);
  if (!(out->hg > 0.0) || !(glm::dot(L - out->c, st.out) > 0.0)) return false;  // the laser behind the edge's plane
  const glm::dvec3 win = glm::normalize(out->c - L);
  out->ce = -glm::dot(win, st.out);
  const double rate = edge_climb_rate(win, st.out, s.n, s.ior);
  out->climb = out->hg * rate / (s.hi - s.lo);
  return rate >= 0.0;
}

// Unfolded across the faces, the path with k reflections is a straight line from x through the edge's
// plane to the laser's image (its height above x's face mirrored once for each odd k), refracted there:
// Snell's invariant as in connect_laser_refracted, the glass's depth the distance from x to the edge's
// plane. It exists when the line meets the edge's plane between k and k + 1 thicknesses above x's face
// (within the lobe's reach) and on the edge along its length.
bool Integrator::edge_path(const glm::dvec3& x, const GlossySlab& s, const GlossyStrip& st, bool on_lo, int k,
                           double alpha, glm::dvec3* w) const {
  const glm::dvec3 L = laser_.position;
  const double d = s.hi - s.lo, n = s.ior;
  const glm::dvec3 m = on_lo ? s.n : -s.n;  // from x's face into the plate
  const double zl = glm::dot(L - x, m);      // the laser's height above x's face
  const glm::dvec3& e = st.out;
  const double hg = glm::dot(st.o - x, e);
  if (!(hg > 1e-3 * d)) return false;
  const double zk = k % 2 == 0 ? zl + k * d : (k + 1) * d - zl;
  const glm::dvec3 Lk = L + (zk - zl) * m;
  const glm::dvec3 to = Lk - x;
  const glm::dvec3 lat = to - glm::dot(to, e) * e;
  const double D = glm::length(lat);
  if (!(D > 0.0) || !(glm::dot(to, e) > hg)) return false;
  const glm::dvec3 u = lat / D;
  const double depth[2] = {hg, glm::dot(to, e) - hg}, index[2] = {n, 1.0};
  // First guess: the sine of the laser's angle to the edge's normal where the line from x meets the edge.
  const glm::dvec3 win = glm::normalize(x + hg * e - L);
  const double p0 = std::min(std::sqrt(std::max(0.0, 1.0 - sqr(glm::dot(win, e)))), 1.0 - 1e-9);
  const double p = snell_invariant(depth, index, 2, D, p0, 1.0);
  const double sg = p / n, cg = std::sqrt(std::max(0.0, 1.0 - sg * sg));
  if (!(cg > 0.0)) return false;
  const glm::dvec3 wg = sg * u + cg * e;  // in the glass, unfolded: x's first segment
  const glm::dvec3 q = x + (hg / cg) * wg;
  const double slack = kGuideEdgeWidths * alpha * hg / cg;
  const double zq = glm::dot(q - x, m);
  if (zq < k * d - slack || zq > (k + 1) * d + slack) return false;
  const double len = glm::length(st.a), along = glm::dot(q - st.o, st.a) / len;
  if (along < -slack || along > len + slack) return false;
  // The laser's direction at the edge (real: the image's height folded back).
  const double ca = std::sqrt(std::max(0.0, 1.0 - p * p));
  glm::dvec3 wa = p * u + ca * e;
  if (k % 2 == 1) wa -= 2.0 * glm::dot(wa, m) * m;
  if (!(laser_.intensity_towards(-wa) > 0.0)) return false;
  *w = wg;
  return true;
}

double Integrator::Ghosts::pdf(int i, const glm::vec3& w) const {
  return double(share[i]) * double(direction_lobe_pdf(lobe[i], w));
}

double Integrator::Ghosts::sum_pdf2(const glm::vec3& w, int r) const {
  double s = 0.0;
  for (int i = 0; i < n; ++i)
    if (reach[i] == r) s += sqr(pdf(i, w));
  return s;
}

// The ghost draws from a non-delta vertex a (for each ghost, with probability kGhostDrawShare): a
// direction drawn from the ghost's lobe, then the camera path's own rules (the BSDF's draws, Russian
// roulette, the guided connections) for the next vertices up to ghosts.reach, whose own laser connections
// are left to the camera path; what the last returns (by its laser connection, or by the guided
// connections of the one before) is the ghost's estimate. The ghost comes back to a's side, so a's
// reflecting lobes share its light: trace_path weights the light of its own draw at a through lobe L by
// the power heuristic's share p_L^2 / (p_L^2 + sum_i p_i^2) over the direction at a (p_L the lobe's density
// times a's survival probability through it, p_i the ghosts' densities, their draw share included); the
// draw from ghost i adds sum_L f_L(w) p_i / (p_L^2 + sum_k p_k^2) times the rest of the path's estimate.
// Both strategies estimate the same rest from the direction on (Russian roulette's later survival
// probabilities change its variance, not its expectation), so the rest cancels from the weights.
void Integrator::ghost_connections(const NeeVertex& a, int vertices_after, int deltas_after, bool roulette,
                                   float eta_scale, const Ghosts& ghosts, Rng& rng, double w, const double* nee_share,
                                   const double* guided_share, const PixelFilm& film, RayCounts* rays,
                                   const GuideTargets* guide_a) const {
  const RenderConfig& rc = config_.render;
  for (int i = 0; i < ghosts.n; ++i) {
    const int reach = ghosts.reach[i];
    if (uniform(rng) >= ghosts.share[i]) continue;
    const float u1 = uniform(rng), u2 = uniform(rng);
    glm::vec3 d;
    if (!sample_direction_lobe(ghosts.lobe[i], u1, u2, &d)) continue;
    const double pi = ghosts.pdf(i, d);
    if (!(pi > 0.0)) continue;
    if ((glm::dot(d, a.sf.ng) > 0.0f) != a.wo_front) continue;  // the ghost comes back to a's side
    const LobeValues lv = a.bsdf.lobes(d);
    // Reach 1 (the next vertex's laser connection): also against a's guided connections.
    const double ph2 = ghosts.sum_pdf2(d, reach) + (reach == 1 && guide_a != nullptr ? guide_a->sum_pdf2(d) : 0.0);
    Spec f(0.0f), f_sum(0.0f);
    double p_sum = 0.0;
    for (const int l : {kDiffuseLobe, kSpecularLobe}) {
      if (!(lv.f_cos[l].x > 0.0f) || !(lv.pdf[l] > 0.0f)) continue;
      double p = lv.pdf[l];
      if (roulette) p *= roulette_q(a.beta * eta_scale * lv.f_cos[l] / lv.pdf[l]);
      f += lv.f_cos[l] * float(pi / (p * p + ph2));
      f_sum += lv.f_cos[l], p_sum += p;
    }
    if (!(f.x > 0.0f) || !(p_sum > 0.0)) continue;
    Spec beta = a.beta * f;
    // What the camera path's roulette would see after a's draw (any positive value keeps the rest unbiased;
    // this one is a draw through the lobes together).
    Spec rr_beta = a.beta * eta_scale * f_sum / float(p_sum);
    double opl = a.opl;
    int medium = a.medium, vertices = vertices_after, deltas = deltas_after;
    bool reflected = true;  // a's draw is a reflection
    glm::dvec3 previous(a.sf.p);
    glm::vec3 o = offset_ray_origin(a.sf.p, a.sf.ng, d);
    double mis = 1.0;
    for (int k = 1; k <= reach; ++k) {
      RayHit hit;
      ++rays->guided;
      if (!embree_.intersect(o, d, 0.0f, kInf, &hit)) break;
      const Surface sf = shading_.surface(hit);
      const double seg = glm::length(glm::dvec3(sf.p) - previous);
      previous = glm::dvec3(sf.p);
      const Spec att = traverse(medium, seg, &opl);
      beta *= att, rr_beta *= att;
      const MaterialPoint mp = shading_.material_at(sf, hit);
      const auto [wo_front, bsdf, volume] = shade(sf, mp, d);
      const NeeVertex v{sf, bsdf, wo_front, volume, medium, vertices, !reflected, beta, opl,
                        !(mp.transmission > 0.0f && vertices > 0)};
      if (k == reach) {  // the ghost's light: the laser connection here
        LaserRay lr;
        RayCounts at_end;
        if (bsdf.has_non_delta() && beta.x > 0.0f && laser_ray(sf, &lr))
          connect_laser(v, lr, nullptr, w * nee_share[reach] * mis, film, &at_end);
        rays->guided += at_end.total();
        break;
      }
      // as trace_path counts and ends the camera path
      bool at_limit = false;
      if (bsdf.has_non_delta()) {
        ++vertices;
        if (vertices >= rc.max_bounces) {
          if (!bsdf.has_delta()) break;  // the camera path meets no laser connection after this one
          at_limit = true;
        }
      }
      const bool rr = !at_limit && vertices >= rc.russian_roulette_from;
      // The guided connections of the vertex before the last reach the last: the ghost's light (the
      // vertices before need no targets: only the last draw's weight, mis, counts).
      GuideTargets guide;
      if (k == reach - 1 && !at_limit && guided_ && beta.x > 0.0f &&
          (bsdf.glossy() || (bsdf.lambertian() && medium < 0 && !parts_.empty()))) {
        const int medium_out_t = volume ? (wo_front ? sf.material : -1) : medium;
        RayCounts own;
        find_guide_targets(sf, bsdf, medium, medium_out_t, &guide, &own);
        rays->guided += own.total();
        if (guide.n > 0) {
          RayCounts at_end;
          guided_connections(v, medium_out_t, rr, rr_beta, guide, rng, w * guided_share[reach - 1], film, &at_end);
          rays->guided += at_end.total();
        }
      }
      const BsdfSample bs = bsdf.sample(uniform3(rng));
      if (!(bs.weight.x > 0.0f || bs.weight.y > 0.0f)) break;
      if (at_limit && !bs.delta) break;
      if (bs.delta && ++deltas > kMaxDeltaEvents) break;
      if (bs.delta && bsdf.has_non_delta()) --vertices;
      reflected = reflected || !bs.transmitted;
      beta *= bs.weight, rr_beta *= bs.weight;
      if (bs.transmitted) rr_beta *= bsdf.eta() * bsdf.eta();
      if (bs.transmitted && volume) medium = wo_front ? sf.material : -1;
      float q = 1.0f;
      if (rr) {
        q = roulette_q(rr_beta);
        if (!(q > 0.0f) || uniform(rng) >= q) break;
        beta /= q, rr_beta /= q;
      }
      mis = 1.0;
      if (guide.n > 0 && !bs.delta) {
        const double pb = double(bsdf.lobes(bs.wi).pdf[bs.lobe]) * q;
        const double pg2 = guide.sum_pdf2(bs.wi);
        if (pg2 > 0.0) mis = pb * pb / (pb * pb + pg2);
      }
      o = offset_ray_origin(sf.p, sf.ng, bs.wi);
      d = bs.wi;
    }
  }
}

[[gnu::always_inline]] inline double Integrator::trace_path(const CameraBlock& block, size_t j, double w,
                                                            const PixelFilm& film, RayCounts* rays) const {
  const RenderConfig& rc = config_.render;
  Rng rng = block.rng[j];
  glm::vec3 o(camera_.position()), d(block.dir[j]);
  Spec beta(1.0f);
  double opl = 0.0;  // optical path from the camera centre, metres
  glm::dvec3 previous = camera_.position();
  int medium = -1, vertices = 0, deltas = 0;
  // The product of eta^2 over the interfaces crossed (pbrt's etaScale): inside a volume of index n, beta
  // holds the radiance's 1 / n^2 compression, which leaving gives back; Russian roulette sees beta times
  // this, so that a path in glass is not stopped (and its survivors weighted up) for a factor it regains.
  float eta_scale = 1.0f;
  bool reflected = false;     // a reflection (delta or not) happened on the way from the camera
  bool last_segment = false;  // after the last NEE vertex: only the environment or emission is left
  double ambient = 0.0;
  // The MIS weight of the laser connection at the next vertex, when the previous vertex also drew guided
  // directions towards it (guided_connections): the BSDF draw's share.
  double next_mis = 1.0;
  // The rays traced so far when the path left its first non-delta vertex: what follows is indirect light.
  // Taken at that vertex's laser connection, and kept once the path leaves it through a non-Dirac lobe.
  const uint64_t no_indirect = UINT64_MAX;
  uint64_t indirect_from = no_indirect, indirect_candidate = no_indirect;
  // The ghosts' MIS weights of the light the path meets at its next vertices (ghost_connections): [i] for
  // the vertex i ahead, the laser connection there (ghost_nee) or the guided connections from there
  // (ghost_guided). 1 where no ghost draw estimates the same light.
  constexpr int kAhead = kMaxGhostReach + 1;
  double ghost_nee[kAhead], ghost_guided[kAhead];
  std::fill_n(ghost_nee, kAhead, 1.0);
  std::fill_n(ghost_guided, kAhead, 1.0);
  // The path follows both branches of its first kMaxDeltaSplits clear interfaces (delta_branches): the
  // reflected one waits here while the transmitted one goes on. Drawing one branch (the front face's F
  // reflected: 8 %) left 27 % of the pixels of 16 paths without a reflection, their error read as 0 where
  // it was 8.5 %, and render.target_relative_error stopped them there.
  struct Branch {
    glm::vec3 o, d;
    Spec beta;
    double opl;
    glm::dvec3 previous;
    int medium, vertices, deltas;
    float eta_scale;
    bool reflected, last_segment;
    double ghost_nee[kAhead], ghost_guided[kAhead];
  };
  Branch pending[kMaxDeltaSplits];
  int n_pending = 0, splits = 0;
  bool camera_ray = true;
  for (;;) {
    for (;; camera_ray = false) {
      const double mis = next_mis;
      next_mis = 1.0;
      for (int i = 0; i + 1 < kAhead; ++i) ghost_nee[i] = ghost_nee[i + 1], ghost_guided[i] = ghost_guided[i + 1];
      ghost_nee[kAhead - 1] = ghost_guided[kAhead - 1] = 1.0;
      RayHit hit;
      if (!next_hit(block, j, camera_ray, o, d, &hit, rays)) {
        gather_environment(beta, &ambient);
        break;
      }
      const Surface sf = surface_at(block, j, camera_ray, hit);
      // From the previous surface point itself, not from the offset origin a few hundred ulps away.
      const double seg = glm::length(glm::dvec3(sf.p) - previous);
      previous = glm::dvec3(sf.p);
      beta *= traverse(medium, seg, &opl);
      const MaterialPoint mp = shading_.material_at(sf, hit);
      gather_emission(beta, mp, &ambient);
      if (last_segment) break;

      const auto [wo_front, bsdf, volume] = shade(sf, mp, d);

      const NeeVertex v{sf, bsdf, wo_front, volume, medium, vertices, !reflected, beta, opl,
                        !(mp.transmission > 0.0f && vertices > 0)};
      // A vertex counts (max_bounces, direct or indirect) only when the path leaves it through a non-Dirac
      // lobe: through a Dirac one (a smooth interface's reflection or transmission, beside a diffuse part)
      // it did not scatter there. At the last vertex it may scatter at, a material with Dirac lobes is
      // still drawn: a Dirac draw goes on, any other ends the path (or, with ambient light, takes the last
      // segment).
      bool at_limit = false;
      // The laser's work (its connections, the guided and ghost draws towards it) only where the run traces
      // it; the path itself (its draws, roulette) is the same either way.
      const bool lit = laser_traced_ && beta.x > 0.0f;
      if (bsdf.has_non_delta()) {
        if (lit) {
          LaserRay lr;
          FirstSegment first;
          const bool ahead = camera_ray && ahead_shadow(block, j, &lr, &first);
          if (ahead || laser_ray(sf, &lr))
            connect_laser(v, lr, ahead ? &first : nullptr, w * mis * ghost_nee[0], film, rays);
        }
        if (beta.y > 0.0f) connect_ambient_lights(v, &ambient, rays);
        ++vertices;
        if (vertices == 1 && rc.max_bounces > 1 && indirect_from == no_indirect) indirect_candidate = rays->total();
        if (vertices >= rc.max_bounces) {
          if (bsdf.has_delta()) {
            at_limit = true;
          } else {
            if (!ambient_on_) break;
            last_segment = true;
          }
        }
      }

      // The ghosts a vertex sees of the laser through a glossy plate (no random numbers: found first, as
      // the guided connections weigh against those whose light the next vertex's laser connection returns).
      Ghosts ghosts;
      if (guided_ && !slabs_.empty() && !last_segment && !at_limit && lit && bsdf.has_non_delta())
        ghost_targets(sf, medium, &ghosts);
      // Guided connections from a glossy vertex whose next vertex may reflect the laser in a narrow lobe.
      GuideTargets guide;
      const bool roulette = !last_segment && !at_limit && vertices >= rc.russian_roulette_from;
      if (guided_ && !last_segment && !at_limit && lit &&
          (bsdf.glossy() || (bsdf.lambertian() && medium < 0 && !parts_.empty()))) {
        const int medium_out_t = volume ? (wo_front ? sf.material : -1) : medium;
        find_guide_targets(sf, bsdf, medium, medium_out_t, &guide, rays);
        if (guide.n > 0)
          guided_connections(v, medium_out_t, roulette, beta * eta_scale, guide, rng, w * ghost_guided[0], film, rays,
                             &ghosts);
      }
      // Ghost draws from a vertex that sees a glossy plate's ghost of the laser.
      if (ghosts.n > 0)
        ghost_connections(v, vertices, deltas, roulette, eta_scale, ghosts, rng, w, ghost_nee, ghost_guided, film, rays,
                          &guide);

      BsdfSample bs, other;
      if (splits < kMaxDeltaSplits && !roulette && bsdf.delta_branches(&other, &bs)) {
        ++splits;
        if (deltas + 1 <= kMaxDeltaEvents) {
          Branch& b = pending[n_pending++];
          b.o = offset_ray_origin(sf.p, sf.ng, other.wi), b.d = other.wi;
          b.beta = beta * other.weight, b.opl = opl, b.previous = previous;
          b.medium = medium, b.vertices = vertices, b.deltas = deltas + 1;
          b.eta_scale = eta_scale, b.reflected = true, b.last_segment = last_segment;
          std::copy_n(ghost_nee, kAhead, b.ghost_nee);
          std::copy_n(ghost_guided, kAhead, b.ghost_guided);
        }
      } else {
        bs = bsdf.sample(uniform3(rng));
      }
      if (!bs.delta && indirect_candidate != no_indirect && indirect_from == no_indirect) indirect_from = indirect_candidate;
      indirect_candidate = no_indirect;
      if (!(bs.weight.x > 0.0f || bs.weight.y > 0.0f)) break;
      if (at_limit && !bs.delta) {
        if (!ambient_on_) break;
        last_segment = true;
      }
      if (bs.delta && ++deltas > kMaxDeltaEvents) break;
      if (bs.delta && bsdf.has_non_delta()) --vertices;
      reflected = reflected || !bs.transmitted;
      beta *= bs.weight;
      if (bs.transmitted && volume) medium = wo_front ? sf.material : -1;
      if (bs.transmitted) eta_scale *= bsdf.eta() * bsdf.eta();
      float q = 1.0f;
      if (roulette) {
        q = roulette_q(beta * eta_scale);
        if (!(q > 0.0f) || uniform(rng) >= q) break;
        beta /= q;
      }
      if ((guide.n > 0 || ghosts.n > 0) && !bs.delta) {
        const double p = double(bsdf.lobes(bs.wi).pdf[bs.lobe]) * q;
        // The next vertex's laser connection: against the guided connections and the ghosts of reach 1.
        const double pg2 = guide.sum_pdf2(bs.wi) + (bs.transmitted ? 0.0 : ghosts.sum_pdf2(bs.wi, 1));
        if (pg2 > 0.0) next_mis = p * p / (p * p + pg2);
        for (int r = 2; r <= kMaxGhostReach && !bs.transmitted; ++r) {
          const double ph2 = ghosts.sum_pdf2(bs.wi, r);
          if (ph2 > 0.0) {  // the light met r - 1 vertices ahead (guided) and r ahead (laser connection)
            const double share = p * p / (p * p + ph2);
            ghost_guided[r - 1] *= share;
            ghost_nee[r] *= share;
          }
        }
      }
      o = offset_ray_origin(sf.p, sf.ng, bs.wi);
      d = bs.wi;
    }
    if (n_pending == 0) break;
    const Branch& b = pending[--n_pending];  // the latest branch left waiting
    o = b.o, d = b.d, beta = b.beta, opl = b.opl, previous = b.previous;
    medium = b.medium, vertices = b.vertices, deltas = b.deltas, eta_scale = b.eta_scale;
    reflected = b.reflected, last_segment = b.last_segment, next_mis = 1.0, camera_ray = false;
    std::copy_n(b.ghost_nee, kAhead, ghost_nee);
    std::copy_n(b.ghost_guided, kAhead, ghost_guided);
  }
  if (indirect_from != no_indirect) rays->indirect += rays->total() - indirect_from;
  return ambient;
}

void Integrator::add_samples(int x, int y, const CameraBlock& block, int s_begin, int s_end, double scale,
                             const TimeAxis& axis, double* bins, RayCounts* rays, double* indirect_bins,
                             ObjectLaser* objects, PixelTotals* out) const {
  const double k = measurement_constant(y) * scale;
  const int lane = x - block.x0;
  if (block.y != y || lane < 0 || lane >= block.lanes || s_begin < block.s0 || s_end > block.s0 + block.spp)
    throw Error("add_samples: pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") is not in its camera block");
  const PixelFilm film{axis, bins, indirect_bins, out, objects};
  // The laser's images in smooth planar faces that land in this pixel (find_camera_glints): with every path
  const CameraGlint* glints[kMaxLaserMirrors * 10];
  size_t n_glints = 0;
  for (const CameraGlint& g : glints_)
    if (g.x == x && g.y == y && n_glints < std::size(glints)) glints[n_glints++] = &g;
  // and the lamps in view that land in it (find_lamps_in_view)
  double lamps = 0.0;
  for (const LampInView& l : lamps_)
    if (l.x == x && l.y == y) lamps += k * l.photons;

  for (int s = s_begin; s < s_end; ++s) {
    throw_if_interrupted();  // one relaxed load per path: a signal stops even a pixel of 10^7 paths
    const size_t j = static_cast<size_t>(s - block.s0) * EmbreeScene::kPacket + static_cast<size_t>(lane);
    const double ct = glm::dot(block.dir[j], camera_.forward());
    const double w = k * ct * ct * ct * ct;  // the camera's cos^4 falloff
    const double before = out->laser_total;
    const double ambient = trace_path(block, j, w, film, rays);
    for (size_t i = 0; i < n_glints; ++i) deposit_laser_light(k * glints[i]->photons, glints[i]->opl, film, false, glints[i]->object);
    const double path = out->laser_total - before;
    out->laser_sq += path * path;
    const double a = lamps > 0.0 ? ambient * w + lamps : ambient * w;
    out->ambient_rate += a;
    out->ambient_sq += a * a;
    out->camera_hits += block.found[j] != 0;
  }
}

double standard_error(double sum, double sq, int n, double scale) {
  if (n < 2) return 0.0;
  // The paths' estimates are scale * c for contributions c; their sample variance over n is the mean's.
  const double dn = n;
  const double var = (sq - sum * sum / dn) / (dn - 1.0);  // of the contributions
  return var > 0.0 ? scale * std::sqrt(var / dn) : 0.0;
}

}  // namespace spadgen::render
