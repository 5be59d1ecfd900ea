// The transient path tracer: camera paths with next-event estimation to the laser (a point emitter, so
// NEE is its only strategy) and to the ambient punctual lights, BSDF sampling for the environment and
// emissive surfaces (their only strategy, so no MIS weights are needed), Russian roulette.
#pragma once
#include <algorithm>
#include <climits>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/rng.h"

#include "camera.h"
#include "core/config.h"
#include "core/time_axis.h"
#include "embree_scene.h"
#include "planar_path.h"
#include "guide.h"
#include "lights.h"
#include "renderer.h"
#include "sphere_search.h"
#include "surface.h"

namespace spadgen::render {

struct PixelTotals {
  double laser_total = 0.0;    // photons per pulse, every contribution
  double out_of_window = 0.0;  // photons per pulse with no periodic image inside the window
  // Photons per pulse whose time of flight (optical path / c) is one laser period or more: returns from
  // beyond the unambiguous range c / (2 f_rep), which fold onto the earlier ones of the next pulse.
  double beyond_period = 0.0;
  int camera_hits = 0;         // samples whose camera ray hit a surface
  // The sum of the squares of each path's contribution to laser_total, for its standard error
  // (standard_error()).
  double laser_sq = 0.0;
  double ambient_rate = 0.0;   // photons per second
  double ambient_sq = 0.0;     // the sum of the squares of each path's contribution to ambient_rate
  // Range of bins written, [bin_lo, bin_hi) (empty when bin_lo >= bin_hi): a pixel's returns usually span
  // a small part of a long window, so only this range is converted and cleared afterwards.
  int64_t bin_lo = INT64_MAX, bin_hi = 0;
};

// The standard error of the mean of n paths' estimates, each `scale` times its contribution c, given the
// sum and the sum of squares of the contributions: scale = n for add_samples with scale 1 / n (the
// fixed-count render: contributions already divided by n), 1 for add_samples with scale 1. 0 for n < 2, where it cannot be estimated.
double standard_error(double sum, double sq, int n, double scale);

// One pixel's laser light split by what returned it: direct paths (the camera sees the vertex that meets
// the laser through transmissions only) by the object of that vertex, indirect paths together. A worker
// keeps one for all its pixels: direct has a slot per object of the scene, and only the objects a pixel
// touched are read and cleared, so a pixel costs what it touches (a pixel sees few objects).
struct ObjectLaser {
  std::vector<double> direct;    // photons per pulse, per object id
  std::vector<int> touched;      // the object ids with a contribution, in the order first met
  std::vector<uint8_t> seen;     // per object id: in touched
  double indirect = 0.0;

  explicit ObjectLaser(size_t objects) : direct(objects, 0.0), seen(objects, 0) {}
  void add(int object, double v) {
    const auto o = static_cast<size_t>(object);
    if (!seen[o]) seen[o] = 1, touched.push_back(object);
    direct[o] += v;
  }
  void clear() {
    for (int o : touched) direct[size_t(o)] = 0.0, seen[size_t(o)] = 0;
    touched.clear();
    indirect = 0.0;
  }
};

// Whether a render of this scene uses guided connections (render.guided_connections, and a material of
// narrow glossy lobe: GGX alpha = roughness^2 in [1e-3, 0.04], the smooth ones being Dirac).
bool guided_connections_active(const scenes::Scene& scene, bool enabled);
// Whether a render of this scene connects vertices to the laser's image in smooth faces: a mesh of a smooth
// material other than a Lambertian one has at most 64 triangles (its planar faces: Integrator's mirrors_) or
// vertex normals (its curved surface: curved_mirrors_).
bool laser_mirrors_active(const scenes::Scene& scene);

// Adds a contribution v arriving at time t: to laser_total, and to the bin of every periodic image
// t + m * period (m any integer) inside [axis.start_s, axis.end_s()), or to out_of_window when there is
// none. A time exactly on a bin edge belongs to the later bin (TimeAxis::bin_of).
// When indirect_bins is not null (an indirect contribution of a split render), the same bins of
// indirect_bins receive v as well.
void deposit(double v, double t, const TimeAxis& axis, double* bins, PixelTotals* out,
             double* indirect_bins = nullptr);

// The next-event ray from a surface point to the laser.
struct LaserRay {
  glm::dvec3 wid{0.0};   // unit direction, double
  double r = 0.0;        // distance
  double intensity = 0;  // photons per pulse per sr the laser sends back along -wid
  glm::vec3 wi{0.0f};    // float direction of the shadow ray
  glm::vec3 origin{0.0f};
};

// The camera rays of one block of pixels, traced ahead as packets: row y, pixels [x0, x0 + lanes) where
// x0 is a multiple of EmbreeScene::kPacket (lanes < kPacket only at the sensor's right edge), one packet
// per sample. The blocks are fixed by the sensor, not by tiles, so a pixel's camera rays always travel in
// the same packet: results do not depend on the tile split or the thread count.
struct CameraBlock {
  int x0 = 0, y = 0, lanes = 0;
  int s0 = 0, spp = 0;   // the samples held: [s0, s0 + spp)
  std::vector<Rng> rng;  // [(s - s0) * kPacket + lane]: the path's stream, after the two jitter draws
  std::vector<glm::dvec3> dir;
  std::vector<RayHit> hit;
  std::vector<uint8_t> found;
  std::vector<Surface> surface;  // at the camera ray's hit
  // The first segment of the laser's shadow ray from that hit, traced ahead as a coherent packet (the
  // rays of neighbouring pixels converge on the laser) whenever the laser shines towards the hit, whether
  // or not the BSDF then uses it: shadow_found is the segment's hit (scenes with transmissive surfaces,
  // shadow_hit) or whether it is blocked (other scenes).
  std::vector<uint8_t> shadow_traced, shadow_found;
  std::vector<RayHit> shadow_hit;
  std::vector<LaserRay> laser;  // that shadow ray (where shadow_traced)
};

// The first segment of a shadow ray, when it was traced ahead (CameraBlock).
struct FirstSegment {
  bool found = false;  // hit something (or, without transmissive surfaces, blocked)
  RayHit hit;
};

class Integrator {
 public:
  // mesh_object: the object (scenes::Objects) of every mesh, for the per-object split of the laser light.
  Integrator(const RenderStageConfig& config, const scenes::Scene& scene, const std::vector<int>& mesh_object,
             const EmbreeScene& embree, const Shading& shading, const Camera& camera, const Laser& laser,
             const Ambient& ambient);

  // The sensor pixels (x, y) in which the camera sees the laser's image in a smooth planar face (find_camera_glints),
  // once each.
  std::vector<std::pair<int, int>> glint_pixels() const;

  // Traces the camera rays of samples [s_begin, s_end) of the block that contains pixel (x, y) (full-sensor
  // coordinates); with begin and end, samples [begin[i], end[i]) of lane i (the block's pixel x0 + i) only,
  // each within [s_begin, s_end), a lane with an empty range not traced. (The paths of sample s of a pixel
  // are the same whichever call traces them.)
  void trace_camera_block(int x, int y, int s_begin, int s_end, const int* begin, const int* end, CameraBlock* block,
                          RayCounts* rays) const;

  // Samples [s_begin, s_end) of pixel (x, y), which the block holds, added to *out and: bins (axis.bins
  // doubles, zeroed by the caller before the first call) photons per pulse per bin (unused when axis.bins
  // == 0); indirect_bins (null: no split) the part of bins carried by paths with two or more non-delta
  // vertices, over the same bin range; objects (null: not asked; cleared by the caller) the laser_total
  // split by object. Each path is weighted by the measurement constant times `scale` (the fixed-count
  // render: 1 / samples_per_pixel; a render to a target error: 1, divided by the final count after).
  void add_samples(int x, int y, const CameraBlock& block, int s_begin, int s_end, double scale, const TimeAxis& axis,
                   double* bins, RayCounts* rays, double* indirect_bins, ObjectLaser* objects, PixelTotals* out) const;

  // FF * optics transmission * p^2 * pi / (4 N^2) for a pixel of row y: photons at the SPAD per unit of
  // photon radiance (cos^4 excluded).
  double measurement_constant(int y) const;

  // The interfaces a straight walk to the laser crossed, as shadow_transmittance records them for
  // connect_laser_refracted.
  struct Crossings {
    static constexpr int kMax = 8;
    struct Crossing {
      glm::dvec3 p;
      glm::vec3 ng;
      int material;
      MaterialPoint mp;
      int medium;  // the walk's medium after the crossing (-1: air)
      uint32_t mesh, triangle;
    };
    // Left uninitialised (a walk writes each crossing it records): the walk runs at every laser connection.
    union Slots {
      Slots() {}
      Crossing c[kMax];
    } slots;
    int n = 0;
    int medium0 = -1;         // the walk's medium at its start
    bool blocked = false;     // an opaque surface (or the crossing limit) stopped the walk
    bool refracting = false;  // it entered or left a volume of index other than 1
    bool planar = true;       // every crossing flat-shaded, and at most kMax of them
    bool complete = true;     // at most kMax crossings
    bool parallel = true;     // every crossing's face parallel to the first's
  };

  // Fraction of light (two channels) that reaches distance `dist` along unit `dir` from `origin`, through
  // transmissive surfaces (straight, ignoring refraction) starting inside volume `medium` (-1: air);
  // *extra_opl receives the optical path added by the media crossed, (n - 1) * length.
  // first: the first segment's result when it was traced ahead (its ray is not counted again). The rays
  // traced are added to *rays (a RayCounts category). crossings: when given, the walk records the
  // interfaces it crosses there, and goes on to the end (or a blocker) even where nothing gets through.
  Spec shadow_transmittance(const glm::vec3& origin, const glm::vec3& dir, float dist, int medium,
                            double* extra_opl, uint64_t* rays, const FirstSegment* first = nullptr,
                            Crossings* crossings = nullptr) const;

  // The shadow ray from sf to the laser; false when the laser sends nothing towards sf.
  bool laser_ray(const Surface& sf, LaserRay* out) const;

 private:
  // add_samples's outputs, handed as one to each laser connection of the pixel's paths.
  struct PixelFilm {
    const TimeAxis& axis;
    double* bins;
    double* indirect_bins;
    PixelTotals* totals;
    ObjectLaser* objects;
  };
  struct NeeVertex;  // integrator.cpp
  void find_guide_targets(const Surface& sf, const Bsdf& bsdf, int medium_r, int medium_t, GuideTargets* out,
                          RayCounts* rays) const;
  void lambertian_guide_targets(const Surface& sf, GuideTargets* out) const;
  // a: a glossy (or Lambertian) vertex; medium_t: the medium on the other side of its surface; roulette:
  // its BSDF draw faces Russian roulette, with the survival probability the camera path at a would have:
  // rr_beta is what its roulette sees there (its throughput times its eta_scale, see trace_path).
  struct Ghosts;
  // ghosts: a's (trace_path's), whose draws of reach 1 aim at the same light (else null).
  void guided_connections(const NeeVertex& a, int medium_t, bool roulette, const Spec& rr_beta,
                          const GuideTargets& guide, Rng& rng, double w, const PixelFilm& film,
                          RayCounts* rays, const Ghosts* ghosts = nullptr) const;
  // The ghosts of the laser a non-delta vertex sees through a glossy plate (reflected inside two or four
  // times), from the air behind the plate or from the plate's back face inside, the ghost of three
  // reflections from its front face inside, and the light entering a plate through its edges, from a vertex
  // inside on either face.
  static constexpr int kMaxGhostReach = 8;
  struct Ghosts {
    static constexpr int kMax = 3 * kMaxGuideTargets;
    DirectionLobe lobe[kMax];
    // The vertices from the one that draws to the one whose laser connection meets ghost i: its
    // reflections, plus one from the air (the entry into the plate): from the air 3 and 5, from the back
    // face inside 2 and 4, from the front face 3; through an edge k (its reflections).
    int reach[kMax] = {};
    float share[kMax] = {};  // the probability that a vertex draws towards ghost i
    int n = 0;
    double pdf(int i, const glm::vec3& w) const;  // per steradian, the share of vertices that draw included
    double sum_pdf2(const glm::vec3& w, int reach) const;  // over the ghosts of that reach
  };
  // medium: the vertex's (-1: air).
  void ghost_targets(const Surface& sf, int medium, Ghosts* out) const;
  // From x inside plate s (slabs_[slab]), on its face lo (on_lo) or hi: the light entering through its edges.
  void edge_ghost_targets(const glm::dvec3& x, const GlossySlab& s, int slab, bool on_lo, Ghosts* out) const;
  // From x inside plate s, the laser's light entering through its lit edge st (GlossyStrip::slab >= 0): the
  // edge's point nearest x along it, in the middle of its thickness (c); x's distance to the edge's plane
  // (hg); the cosine of the laser's incidence at c (ce); how many thicknesses that light climbs along the
  // faces' normal on its way to x (climb: about how many reflections between the faces it makes). False
  // when the laser is behind the edge's plane. From x on the face lo (on_lo) or hi: edge_path, the path
  // with k reflections (*w: its direction at x), when it meets the edge within kGuideEdgeWidths of a lobe
  // of this alpha.
  struct EdgeEntry {
    glm::dvec3 c{0.0};
    double hg = 0.0, ce = 0.0, climb = 0.0;
  };
  bool edge_entry(const glm::dvec3& x, const GlossySlab& s, const GlossyStrip& st, EdgeEntry* out) const;
  bool edge_path(const glm::dvec3& x, const GlossySlab& s, const GlossyStrip& st, bool on_lo, int k, double alpha,
                 glm::dvec3* w) const;
  // a: the non-delta vertex (vertices_after, deltas_after: the path's non-delta vertices including a and
  // its delta events so far; roulette: a's BSDF draw faces Russian roulette; eta_scale: the camera path's, at a).
  // nee_share[r], guided_share[r]: the weights the ghost draws of earlier vertices leave to the light met
  // r vertices ahead by its laser connection, and by the guided connections from there (trace_path's).
  void ghost_connections(const NeeVertex& a, int vertices_after, int deltas_after, bool roulette,
                         float eta_scale, const Ghosts& ghosts, Rng& rng, double w, const double* nee_share,
                         const double* guided_share, const PixelFilm& film, RayCounts* rays,
                         const GuideTargets* guide_a) const;
  // Russian roulette's survival probability for a path of throughput beta: its laser channel, or the larger
  // channel when the scene has ambient light, at most 0.95.
  float roulette_q(const Spec& beta) const {
    return std::min(0.95f, ambient_on_ ? std::max(beta.x, beta.y) : beta.x);
  }

  // One camera path, sample j of `block` (pbrt's Li): deposits its laser light, weighted by the pixel's
  // measurement w, and returns the ambient photon radiance it gathered, which add_samples weights by w.
  double trace_path(const CameraBlock& block, size_t j, double w, const PixelFilm& film, RayCounts* rays) const;

  // Packet plumbing: the camera ray's hit and surface, and the laser shadow ray from that hit with its
  // first segment, come from trace_camera_block, which traces them as packets (neighbouring pixels' rays
  // are coherent, and their shadow rays converge on the laser); every later ray is traced one at a time.
  bool next_hit(const CameraBlock& block, size_t j, bool camera_ray, const glm::vec3& o, const glm::vec3& d,
                RayHit* hit, RayCounts* rays) const;
  Surface surface_at(const CameraBlock& block, size_t j, bool camera_ray, const RayHit& hit) const;
  bool ahead_shadow(const CameraBlock& block, size_t j, LaserRay* lr, FirstSegment* first) const;

  // What every path vertex sets up: a segment of length seg (metres) in `medium` (-1: air) gives its
  // Beer-Lambert attenuation (1 in air or a clear medium) and adds its optical length to *opl; the surface
  // point reached along d gives its BSDF and sides.
  Spec traverse(int medium, double seg, double* opl) const;
  struct Shaded;  // integrator.cpp
  Shaded shade(const Surface& sf, const MaterialPoint& mp, const glm::vec3& d) const;

  // Next-event estimation to the laser from v along lr (first: the shadow ray's first segment when it was
  // traced ahead, else null).
  // The laser's connection from v through the refracting interfaces the straight walk to it crossed
  // (parallel planar faces of volumes: a plate); false when the refracted path does not cross the same
  // surfaces (then the straight connection is used).
  // p_guess: a first guess of Snell's invariant (< 0: from the straight line to the laser). echoes: the light
  // reflected between pairs of faces too, each traced with a probability by its reflectance.
  bool connect_laser_refracted(const NeeVertex& v, const LaserRay& lr, const Crossings& cx, double w,
                               const PixelFilm& film, RayCounts* rays, bool echoes, double p_guess = -1.0) const;
  // The laser's connection from v through the planar faces the straight walk crossed when they are not all
  // parallel (solve_planar_path); false when no refracted path crosses the same faces (then the straight
  // connection is used).
  // echoes: the light reflected between pairs of faces too, as connect_laser_refracted's.
  bool connect_laser_planar(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film, RayCounts* rays,
                            bool echoes) const;
  // The laser's connection from v through faces the straight walk crossed of which some are shaded (triangles of
  // smooth meshes: a glass sphere), by solve_planar_path on the triangles the path meets. Nothing where no path is
  // found (the straight connection is not used).
  void connect_laser_shaded(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film, RayCounts* rays) const;
  // The light of a path solved for connect_laser_planar, connect_laser_shaded or connect_laser_mirrors, traced:
  // segment j < k must meet a face of material[j] and normal +-ng[j] (reflect[j]: reflecting off it; null:
  // crossing every face), index and media those of each segment; false where it does not (nothing deposited).
  // rays: the category its segments count in (RayCounts::refracted or mirror). shaded[j]: face j's Fresnel
  // factor at its shading normal (null: none).
  // The segments of a path solved for those connections, traced from v: segment j < k must meet a face of
  // material[j] first, on the plane planned (shaded[j]: near its point; else of normal +-ng[j] through it; reflect[j]:
  // from its front), the last one nothing. faces[j]: the surface met. Astray: a segment met another surface, or none;
  // Blocked / Transmissive: the last one met an opaque / a transmissive surface.
  enum class PathTrace { Clear, Astray, Blocked, Transmissive };
  struct FaceHit {
    Surface sf;
    RayHit hit;
  };
  // Left uninitialised (the trace writes each face it meets): a path's connection runs at many vertices.
  union FaceHits {
    FaceHits() {}
    FaceHit f[kMaxPlanarFaces];
  };
  // (from origin, a vertex's point, whose surface normal origin_n its rays step off along)
  PathTrace trace_planar_path(const glm::vec3& origin, const glm::vec3& origin_n, const PlanarPath& path, const int* material,
                              const glm::vec3* ng, const bool* reflect, const bool* shaded, uint64_t* rays, FaceHit* faces) const;
  bool deposit_planar_path(const NeeVertex& v, const PlanarPath& path, const int* material, const glm::vec3* ng,
                           const double* index, const int* media, const bool* reflect, double w, const PixelFilm& film,
                           uint64_t* rays, const bool* shaded = nullptr) const;
  // The laser's connection from v through refracting planar faces of which one or more are rough (a frosted plate,
  // or frosted on one side), by a drawn microfacet normal per rough face and the path solved for them;
  // rough_crossings: whether it takes the crossings.
  void connect_laser_rough(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film, RayCounts* rays) const;
  bool rough_crossings(const Crossings& cx) const;
  // A rough plate: a small flat refracting volume (a mesh, or the meshes of one glTF node) with a rough face (alpha
  // at least kRoughCrossingAlpha), its two largest parallel planes n . p = lo and hi and their faces' materials;
  // the laser's light through it to the vertices whose straight walk to the laser does not cross it
  // (connect_laser_rough_slabs).
  struct RoughSlab {
    glm::dvec3 n;
    double lo, hi;
    int material[2];  // lo's, hi's
  };
  static constexpr size_t kMaxRoughSlabs = 8;
  std::vector<RoughSlab> rough_slabs_;
  void connect_laser_rough_slabs(const NeeVertex& v, const Crossings& cx, double w, const PixelFilm& film, RayCounts* rays) const;
  static constexpr int kMaxRoughFaces = 4;
  static constexpr float kRoughCrossingAlpha = scenes::kRoughCrossingAlpha;  // (scenes/scene.h: why 0.025)
  // The alpha with which connect_laser_rough evaluates a smoother face's BSDF on a chain with rough ones, at its
  // own normal: its transmission without D in the limit of a narrow lobe (the shadowing's share within 1e-4 up to
  // 80 degrees), a smooth face's Dirac lobe in the integral over the half vectors.
  static constexpr float kDeltaAlpha = 2e-3f;
  // The laser's light reflected to v by the smooth planar faces of mirrors_.
  void connect_laser_mirrors(const NeeVertex& v, double w, const PixelFilm& film, RayCounts* rays) const;
  // A path of the laser's image in a smooth planar face of mirrors_ (for_each_mirror_path): the path solved from a
  // point x and what it meets, segment by segment; trips: -1 off the face itself, else the round trips inside the
  // plate after its other face.
  struct MirrorPath {
    PlanarPath path;
    double index[kMaxPlanarFaces + 1];
    int media[kMaxPlanarFaces + 1], material[kMaxPlanarFaces];
    bool reflect[kMaxPlanarFaces];
    glm::vec3 normals[kMaxPlanarFaces];
    int mirror = -1, trips = -1;
  };
  // sink(path, q) for each path from x to the point L (the laser, a lamp) off the faces of mirrors_ (off the face, and,
  // behind a plate's face, off its other face after 0 or more round trips): q the probability it was drawn with.
  // draw_at: where its echoes' draws are seen from (vertex_uniform); null: every echo while its share is at least
  // 1e-6, q = 1.
  template <class Sink>
  void for_each_mirror_path(const glm::dvec3& x, const glm::dvec3& L, const glm::vec3* draw_at, Sink&& sink) const;
  // The light of a traced mirror or refracted path (faces: what trace_planar_path met): the faces' Fresnel factors
  // and the media's absorption along it; *opl its optical path.
  Spec planar_path_throughput(const PlanarPath& path, const FaceHit* faces, const double* index, const int* media,
                              const bool* reflect, const bool* shaded, double* opl) const;
  // The laser's images in the faces of mirrors_ as the camera sees them (laser -> face -> lens, and a plate's
  // echoes behind its face): no path finds them, the lens being a point too. Each lands in one pixel, whose every
  // path add_samples gives it (the same light each time: no noise). Found once, when the integrator is built.
  struct CameraGlint {
    int x = 0, y = 0;      // sensor pixel
    double photons = 0.0;  // per pulse at the SPAD, per unit of measurement_constant
    double opl = 0.0;      // optical path from the laser, metres
    int object = -1;       // the face's object (off the face, or off its other face through it), -1: an echo (indirect)
  };
  std::vector<CameraGlint> glints_;
  void find_camera_glints();
  // A mirror path from the camera centre (for_each_mirror_path) of a point of `intensity` towards it: traced; false
  // unless it lands in a pixel (*x, *y) and meets each face, then nothing; *t its faces' and media's light, *opl its
  // optical path.
  bool camera_mirror_path(const MirrorPath& mp, double intensity, Spec* t, double* opl, int* x, int* y) const;
  // The glTF point and spot lights in view (a lamp the camera sees: a point no camera ray meets), each in the pixel
  // it lands in, seen through what lies between (straight, as shadow rays), and their images in smooth planar faces
  // (mirrors_, as the laser's glints): photons per second at the SPAD per
  // unit of measurement_constant, which add_samples adds to every path's ambient light. Found once, when built.
  struct LampInView {
    int x = 0, y = 0;
    double photons = 0.0;
  };
  std::vector<LampInView> lamps_;
  void find_lamps_in_view();
  // The laser's light refracted to v through each smooth glass mesh of curved_refractors_ alone, along every path
  // the search finds.
  void connect_laser_curved_refractors(const NeeVertex& v, double w, const PixelFilm& film, RayCounts* rays) const;
  // Whether the straight walk from x crossed exactly one mesh of curved_refractors_, in and out, from air, and the
  // search runs for x there (its light is connect_laser_curved_refractors').
  bool through_curved_refractor_alone(const Crossings& cx, const glm::dvec3& x) const;
  // The laser's light reflected to v by the smooth curved meshes of curved_mirrors_.
  void connect_laser_curved_mirrors(const NeeVertex& v, double w, const PixelFilm& film, RayCounts* rays) const;
  // A uniform number in [0, 1) seen from vertex position p: a hash of it, the light seed, a salt and two small
  // integers. The echo of faces a, b (connect_laser_refracted, connect_laser_planar: kEchoSalt, a, b); face j's
  // microfacet normal (connect_laser_rough: kRoughSalt, j, 0 and 1). A draw there from the path's stream would
  // move the path's later draws.
  double vertex_uniform(const glm::vec3& p, uint64_t salt, int a, int b) const;
  static constexpr uint64_t kEchoSalt = 0x6563686f6563686full;   // "echoecho" (+ m - 1 for the m-th order)
  // A laser-side echo's draw: traced with probability min(1, its share of the light / kEchoTraced); its orders
  // (round trips between the same two faces) kept while their share (R_a R_b)^m is at least kEchoShareKept, as
  // the mirrors' round trips (connect_laser_refracted, connect_laser_planar).
  static constexpr double kEchoTraced = 0.01, kEchoShareKept = 1e-6;
  // How many orders of the echo between two faces of reflectance product r_ab a connection traces: the first
  // always, then while their share is at least kEchoShareKept, at most `fit` (what the path's arrays hold).
  static int echo_orders(double r_ab, int fit);
  // Whether vertex p's draw traces order m of the echo between faces a and b ((r_ab)^m of the light): the
  // probability it is traced with, 0 where it is not.
  double echo_drawn(const glm::vec3& p, double r_ab, int m, int a, int b) const;
  static constexpr uint64_t kRoughSalt = 0x726f756768726f75ull;  // "roughrou"

  // The refractive index of medium `medium` (-1: air, 1).
  double medium_ior(int medium) const { return medium < 0 ? 1.0 : double(shading_.material(medium).point.ior); }
  static constexpr int kMaxLaserSteps = 3 * Crossings::kMax + 1;  // an echo's segments: the layers, and twice those between its faces
  // The layers between a vertex and the laser across a straight walk's parallel faces: their media (-1: air),
  // indices and thicknesses along the faces' normal nrm (towards the laser), and the laser's lateral offset D
  // along u.
  struct RefractedLayers {
    int k = 0;  // faces
    int media[Crossings::kMax + 1];
    double depth[Crossings::kMax + 1], index[Crossings::kMax + 1];
    glm::dvec3 nrm, u;
    double D = 0.0, p_max = 1e30;
  };
  // p_out, cos_out (null: not asked): the path's Snell invariant, and each segment's cosine to the faces' normal
  // (when the path was solved).
  bool connect_laser_along(const NeeVertex& v, const RefractedLayers& ly, const Crossings& cx, const int* layer,
                           const bool* back, int n, double p0, double w, const PixelFilm& film, RayCounts* rays,
                           double* p_out = nullptr, double* cos_out = nullptr) const;
  // reflected: the light reflected on its way from the laser (an echo between a plate's faces): the object's
  // indirect light, never its own return.
  void deposit_laser(const NeeVertex& v, double value, double opl, const PixelFilm& film, bool reflected = false) const;
  // Laser light `value` of optical path opl into the film: its time bin (and indirect_bins' when `indirect`: a path
  // of two or more scattering vertices), the totals, and the object split (object -1: the indirect rest).
  void deposit_laser_light(double value, double opl, const PixelFilm& film, bool indirect, int object) const;
  // The photons at the SPAD, per unit of measurement_constant, of a point of intensity 1 and spread 1 seen from the
  // camera centre along unit d (a glint, a lamp): the aperture A = pi f^2 / (4 N^2), which is measurement_constant's
  // p^2 pi / (4 N^2) times (f / p)^2, seen at cos(theta).
  double point_image(const glm::dvec3& d) const;
  // From a vertex inside a plate: the laser's light that enters through one of the plate's edges and
  // reaches the vertex without a reflection (another path than the straight walk's, cx, unless that one
  // crossed the same edge).
  void connect_laser_edges(const NeeVertex& v, const LaserRay& lr, const Crossings& cx, double w,
                           const PixelFilm& film, RayCounts* rays) const;
  MaterialPoint strip_material(const GlossyStrip& st, const glm::dvec3& c) const;
  void connect_laser(const NeeVertex& v, const LaserRay& lr, const FirstSegment* first, double w,
                     const PixelFilm& film, RayCounts* rays) const;

  // The ambient estimate, in the ambient channel (beta.y): light from the environment where the path
  // escapes, from emissive surfaces it hits, and from punctual ambient lights by next-event estimation.
  void gather_environment(const Spec& beta, double* ambient) const;
  void gather_emission(const Spec& beta, const MaterialPoint& mp, double* ambient) const;
  void connect_ambient_lights(const NeeVertex& v, double* ambient, RayCounts* rays) const;

  const RenderStageConfig& config_;
  const std::vector<int>& mesh_object_;
  const EmbreeScene& embree_;
  const Shading& shading_;
  const Camera& camera_;
  const Laser& laser_;
  bool refractive_ = false;  // a volume material with ior != 1: laser connections may refract
  // The laser reaches vertices by paths other than the straight line (mirrors, refracting volumes): a vertex
  // outside the beam along the straight line is still connected (laser_ray).
  bool laser_images_ = false;
  bool guided_ = false;      // a glossy material of narrow lobe (alpha <= kGuideMaxAlpha): guided connections
  std::vector<GlossyPart> parts_;    // the triangles of small meshes (plates) of such materials
  std::vector<GlossyStrip> strips_;  // their slivers (pairs of triangles)
  bool edges_ = false;               // a strip is a plate's edge (GlossyStrip::slab)
  std::vector<GlossySlab> slabs_;    // the plates among them (volumes of parallel faces)
  // A smooth planar face of a small mesh, which reflects the laser onto the scene (a clear plate's face, a flat
  // mirror): the plane n . p = offset, n out of the mesh; depth: a plate's thickness behind the face to its
  // parallel other face (0: none, or not a volume). At most kMaxLaserMirrors of them.
  // The face's extent: its corners' bounds along two directions in its plane.
  struct LaserMirror {
    glm::dvec3 n;
    double offset = 0.0, depth = 0.0;
    int material = -1;
    bool volume = false;
    bool two_sided = false;  // a flat mesh that is no volume (a sheet, a mirror): seen from either side
    glm::dvec3 e[2];
    double lo[2] = {1e300, 1e300}, hi[2] = {-1e300, -1e300};
    int mesh = -1;  // the mesh whose face it is
  };
  static constexpr size_t kMaxLaserMirrors = 16;
  std::vector<LaserMirror> mirrors_;
  // A smooth mesh of more than kMaxPartsPerMesh triangles with vertex normals: its bounding box's centre, half
  // diagonal, and its corners' least distance from that centre. curved_mirrors_: those that reflect the laser onto
  // the scene off their curved surface, on their front (glTF) side (a chrome sphere); curved_refractors_: those
  // that bound a refracting volume (a glass sphere). At most kMaxCurvedMeshes of each.
  struct CurvedMesh {
    uint32_t mesh = 0;
    int material = -1;
    glm::dvec3 centre{0.0};
    double radius = 0.0, inner = 0.0;
    // (curved_refractors_) the searches of its paths (render/sphere_search.h), through the sphere of radius inner;
    // where the mesh is not a sphere (its farthest corner more than 2 % farther than its nearest), also through
    // those of their geometric mean and of the farthest.
    std::vector<SphereSearch> searches;
  };
  // Whether connect_laser_curved_refractors searches mesh m's paths to x: x and the laser outside the sphere of
  // its search (radius m.inner).
  bool curved_refractor_searched(const CurvedMesh& m, const glm::dvec3& x) const;
  static constexpr size_t kMaxCurvedMeshes = 8;
  // The steps of connect_laser_curved_refractors' search over the laser's rays through a sphere (uniform in their
  // angle of incidence).
  static constexpr int kCurvedRefractorSteps = 64;
  static constexpr int kMaxCurvedRefractorPaths = 8;  // the paths connect_laser_curved_refractors takes per mesh
  static constexpr int kMaxCurvedRefractorSeeds = 16;  // the seeds it takes of each search
  std::vector<CurvedMesh> curved_mirrors_, curved_refractors_;
  const Ambient& ambient_;
  bool transmission_ = false;
  bool ambient_on_ = false;
  bool laser_traced_ = true;  // RenderStageConfig::trace_laser
  double optics_ = 1.0;
  double period_opl_ = 0.0;  // c / f_rep: the optical path of one laser period, metres
};

}  // namespace spadgen::render
