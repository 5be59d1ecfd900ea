#include "renderer.h"

#include <tbb/blocked_range.h>
#include <tbb/parallel_for.h>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/units.h"
#include "renderer_impl.h"

namespace spadgen::render {
namespace {

std::string rect_str(const PixelRect& r) {
  return "[" + std::to_string(r.x0) + ", " + std::to_string(r.y0) + ", " + std::to_string(r.width) + ", " +
         std::to_string(r.height) + "]";
}

// One pixel's split into its ground-truth slots: slot j receives its object's direct light; the direct
// light of objects in no slot is summed in ascending object order, so the sums do not depend on the order
// the paths met them (which they do not anyway: samples come in a fixed order).
void put_object_laser(ObjectLaser* objects, int64_t pixel, GroundTruthTile* gt, double scale) {
  const auto slots = static_cast<size_t>(gt->max_layers);
  const int32_t* ids = gt->object_slot_id.data() + size_t(pixel) * slots;
  float* laser = gt->object_laser.data() + size_t(pixel) * slots;
  std::sort(objects->touched.begin(), objects->touched.end());
  double other = 0.0;
  for (int o : objects->touched) {
    const int32_t* slot = std::find(ids, ids + slots, o);
    if (slot != ids + slots) laser[slot - ids] = static_cast<float>(objects->direct[size_t(o)] * scale);
    else other += objects->direct[size_t(o)];
  }
  gt->direct_other_laser[size_t(pixel)] = static_cast<float>(other * scale);
  gt->indirect_laser[size_t(pixel)] = static_cast<float>(objects->indirect * scale);
}

// The scene with every world position measured from `origin`, in double before rounding to float once
// (each mesh's from its offset: the renderer's meshes have offset 0).
scenes::Scene centred_on(const scenes::Scene& world, const glm::dvec3& origin) {
  scenes::Scene s = world;
  for (scenes::Mesh& m : s.meshes) {
    const glm::dvec3 shift = m.offset - origin;
    for (glm::vec3& p : m.positions) p = glm::vec3(glm::dvec3(p) + shift);
    m.offset = glm::dvec3(0.0);
  }
  for (scenes::Light& l : s.lights) l.position -= origin;
  for (scenes::Camera& c : s.cameras) c.world_from_camera[3] -= glm::dvec4(origin, 0.0);
  for (scenes::Node& n : s.nodes)
    if (n.loaded) n.world[3] -= glm::dvec4(origin, 0.0);
  return s;
}

}  // namespace

Renderer::Impl::Impl(const scenes::Scene& s, const RenderStageConfig& c)
    : origin(Camera(c.camera, s).position()),
      scene(centred_on(s, origin)),
      objects(scenes::objects_of(scene)),
      config(c),
      camera(config.camera, s, origin),
      laser(make_laser(config, camera, scene, &laser_light)),
      ambient_weights(rgb_weights_over(config.ambient.wavelength_m, config.ambient.bandwidth_m)),
      ambient(make_ambient(config, scene, ambient_weights, laser_light)),
      embree(scene),
      shading(scene, config.laser.wavelength_m, ambient_weights,
              photons_per_second_per_photometric_unit(config.ambient.wavelength_m, config.ambient.bandwidth_m)),
      integrator(config, scene, objects.mesh_object, embree, shading, camera, laser, ambient) {}

void Renderer::Impl::check_rect(const PixelRect& r, const char* what) const {
  if (r.width <= 0 || r.height <= 0 || r.x0 < 0 || r.y0 < 0 || r.x1() > camera.width() || r.y1() > camera.height())
    throw Error(std::string(what) + " " + rect_str(r) + " is empty or outside the " +
                std::to_string(camera.width()) + " x " + std::to_string(camera.height()) + " sensor");
}

Renderer::Renderer(const scenes::Scene& scene, const RenderStageConfig& config)
    : impl_(std::make_unique<Impl>(scene, config)) {}

Renderer::~Renderer() = default;

glm::dvec3 Renderer::laser_position() const { return impl_->laser.position + impl_->origin; }

std::vector<std::pair<int, int>> Renderer::glint_pixels() const { return impl_->integrator.glint_pixels(); }

double Renderer::photons_per_pulse() const {
  const LaserConfig& l = impl_->config.laser;
  return spadgen::photons_per_pulse(l.average_power_W, l.repetition_rate_Hz, l.wavelength_m);
}

static_assert(Renderer::kBlockPixels == EmbreeScene::kPacket, "a block of pixels is one packet of camera rays");

size_t Renderer::bytes_per_thread(int samples_per_pixel) {
  constexpr size_t per_sample = sizeof(Rng) + sizeof(glm::dvec3) + 2 * sizeof(RayHit) + 3 * sizeof(uint8_t) +
                                sizeof(Surface) + sizeof(LaserRay);
  return static_cast<size_t>(samples_per_pixel) * EmbreeScene::kPacket * per_sample;
}

TransientTile Renderer::transient(const PixelRect& rect, const PixelRect& data_rect, const TimeAxis& axis,
                                  RenderStats* stats, GroundTruthTile* gt) const {
  const Impl& im = *impl_;
  im.check_rect(data_rect, "transient data_rect");
  if (rect.x0 < data_rect.x0 || rect.y0 < data_rect.y0 || rect.x1() > data_rect.x1() || rect.y1() > data_rect.y1())
    throw Error("transient rect " + rect_str(rect) + " is not inside its data_rect " + rect_str(data_rect));
  if (axis.bins < 0 || (axis.bins > 0 && !(axis.bin_width_s > 0.0)) || !(axis.period_s >= 0.0))
    throw Error("transient time axis: expected bins >= 0, a positive bin width and a period >= 0");
  if (gt && (gt->rect != rect || gt->object_laser.size() != size_t(rect.count()) * size_t(gt->max_layers)))
    throw Error("transient: the ground truth given for the object split is not that of rect " + rect_str(rect));

  TransientTile tile;
  tile.rect = rect;
  tile.data_rect = data_rect;
  tile.axis = axis;
  const auto n = static_cast<size_t>(data_rect.count());
  const auto bins = static_cast<size_t>(axis.bins);
  tile.transient.assign(n * bins, 0.0f);
  const bool split = im.config.render.split_direct_indirect && bins > 0;
  if (split) tile.transient_indirect.assign(n * bins, 0.0f);
  tile.laser_total.assign(n, 0.0);
  tile.out_of_window.assign(n, 0.0);
  tile.ambient_rate.assign(n, 0.0f);
  tile.beyond_period.assign(n, 0.0);
  tile.laser_se.assign(n, 0.0f);
  tile.ambient_se.assign(n, 0.0f);
  tile.samples.assign(n, im.config.render.samples_per_pixel);
  if (bins > 0) {
    tile.bin_lo.assign(n, 0);
    tile.bin_hi.assign(n, 0);
  }
  const RenderConfig& rc = im.config.render;

  RayCounts tile_rays;  // the tasks' rays, added under rays_mutex
  std::mutex rays_mutex;
  const auto add_rays = [&](const RayCounts& r) {
    const std::lock_guard<std::mutex> lock(rays_mutex);
    tile_rays += r;
  };
  std::vector<int> camera_hits(n, 0);
  // Stores pixel (x, y)'s totals, and its bins scaled by `scale` (1: as accumulated), clearing them.
  // se: of the laser total; ambient_se: of the ambient rate.
  const auto store = [&](int x, int y, const PixelTotals& t, double scale, int paths, double se, double ambient_se,
                         double* acc, double* acc_indirect) {
    const auto i = static_cast<size_t>(data_rect.index(x, y));
    float* out = tile.transient.data() + i * bins;
    for (int64_t b = t.bin_lo; b < t.bin_hi; ++b) {
      out[b] = static_cast<float>(acc[size_t(b)] * scale);
      acc[size_t(b)] = 0.0;
    }
    if (split) {
      float* ind = tile.transient_indirect.data() + i * bins;
      for (int64_t b = t.bin_lo; b < t.bin_hi; ++b) {
        ind[b] = static_cast<float>(acc_indirect[size_t(b)] * scale);
        acc_indirect[size_t(b)] = 0.0;
      }
    }
    if (bins > 0 && t.bin_lo < t.bin_hi) {
      tile.bin_lo[i] = static_cast<int32_t>(t.bin_lo);
      tile.bin_hi[i] = static_cast<int32_t>(t.bin_hi);
    }
    tile.laser_total[i] = t.laser_total * scale;
    tile.out_of_window[i] = t.out_of_window * scale;
    tile.beyond_period[i] = t.beyond_period * scale;
    camera_hits[i] = t.camera_hits;
    tile.ambient_rate[i] = static_cast<float>(t.ambient_rate * scale);
    tile.laser_se[i] = static_cast<float>(se);
    tile.ambient_se[i] = static_cast<float>(ambient_se);
    tile.samples[i] = paths;
  };
  constexpr int kPacket = EmbreeScene::kPacket;
  constexpr int kChunk = kSamplesAhead;  // CameraBlock's memory
  if (!rc.target_relative_error) {
    tbb::parallel_for(tbb::blocked_range<int>(data_rect.y0, data_rect.y1()), [&](const tbb::blocked_range<int>& rows) {
      // Accumulated in double per pixel; stored as float. Pixels are independent, so the split into tasks
      // does not change any result. Only the bins a pixel touched are copied out and cleared again.
      const int spp = rc.samples_per_pixel;
      std::vector<double> acc(bins * kPacket, 0.0), acc_indirect(split ? bins * kPacket : 0, 0.0);
      RayCounts rays;
      CameraBlock block;
      std::vector<ObjectLaser> objects(kPacket, ObjectLaser(gt ? im.objects.list.size() : 0));
      for (int y = rows.begin(); y < rows.end(); ++y)
        for (int bx = data_rect.x0 - data_rect.x0 % kPacket; bx < data_rect.x1(); bx += kPacket) {
          // Camera rays travel in packets fixed by the sensor (EmbreeScene::kPacket pixels of a row), so a
          // tile edge inside a block traces the whole block (and shades only its own pixels). The samples
          // are traced ahead kChunk at a time, each pixel's in order: the same sums as all at once, in
          // bounded memory (a block of 400,000 paths per pixel held 1.6 GB and took seconds to allocate).
          const int lanes = std::min(kPacket, im.camera.width() - bx);
          const int i0 = std::max(0, data_rect.x0 - bx), i1 = std::min(lanes, data_rect.x1() - bx);
          PixelTotals tot[kPacket];
          for (int c0 = 0; c0 < spp; c0 += kChunk) {
            const int c1 = std::min(spp, c0 + kChunk);
            im.integrator.trace_camera_block(bx, y, c0, c1, nullptr, nullptr, &block, &rays);
            for (int i = i0; i < i1; ++i) {
              const int x = bx + i;
              const bool split_objects = gt && rect.contains(x, y);
              im.integrator.add_samples(x, y, block, c0, c1, 1.0 / spp, axis, acc.data() + size_t(i) * bins, &rays,
                                        split ? acc_indirect.data() + size_t(i) * bins : nullptr,
                                        split_objects ? &objects[size_t(i)] : nullptr, &tot[i]);
            }
          }
          for (int i = i0; i < i1; ++i) {
            const int x = bx + i;
            if (gt && rect.contains(x, y)) {
              put_object_laser(&objects[size_t(i)], rect.index(x, y), gt, 1.0);
              objects[size_t(i)].clear();
            }
            store(x, y, tot[i], 1.0, spp, standard_error(tot[i].laser_total, tot[i].laser_sq, spp, spp),
                  standard_error(tot[i].ambient_rate, tot[i].ambient_sq, spp, spp), acc.data() + size_t(i) * bins,
                  split ? acc_indirect.data() + size_t(i) * bins : nullptr);
          }
        }
      add_rays(rays);
    });
  } else {
    // To a target relative error, in two rounds per pixel. The first, samples_per_pixel paths (laser
    // totals only), estimates the paths' relative spread and decides the count n of the second: the
    // count whose standard error would be the target, at least samples_per_pixel, at most
    // max_samples_per_pixel. The estimate is the second round's n paths, samples [first, first + n) of
    // the pixel: fresh paths, independent of the decision, so it is unbiased (a rule that stops on the
    // paths it averages stops early where the rare bright paths have not come yet, and is biased low;
    // tests/render/accuracy_test.cpp checks the estimate against an independent render). The block's 16 pixels render together, and a pixel's rounds depend
    // on its own paths only, so the result does not depend on tiles or threads.
    const double target = *rc.target_relative_error;
    const int first = rc.samples_per_pixel, most = std::max(rc.max_samples_per_pixel, first);
    const TimeAxis totals_only{axis.start_s, axis.bin_width_s, 0, axis.period_s};
    tbb::parallel_for(tbb::blocked_range<int>(data_rect.y0, data_rect.y1()), [&](const tbb::blocked_range<int>& rows) {
      std::vector<double> acc(bins * kPacket, 0.0), acc_indirect(split ? bins * kPacket : 0, 0.0);
      RayCounts rays;
      CameraBlock block;
      std::vector<ObjectLaser> objects(kPacket, ObjectLaser(gt ? im.objects.list.size() : 0));
      for (int y = rows.begin(); y < rows.end(); ++y) {
        const double ambient_floor = im.config.row_ambient_floor.empty() ? 0.0 : im.config.row_ambient_floor[size_t(y)];
        for (int bx = data_rect.x0 - data_rect.x0 % kPacket; bx < data_rect.x1(); bx += kPacket) {
          // Every pixel of the block renders, as in the fixed-count render (a tile edge inside a block
          // renders the whole block and keeps its own pixels): so the lanes traced together, and with
          // them each path, do not depend on the tiles.
          const int lanes = std::min(kPacket, im.camera.width() - bx);
          int begin[kPacket], end[kPacket];
          // Samples [begin[i], end[i]) of lane i, in chunks; each lane's share goes to add(i, b, e).
          const auto render_rounds = [&](auto add) {
            int lo = INT32_MAX, hi = 0;
            for (int i = 0; i < kPacket; ++i)
              if (begin[i] < end[i]) lo = std::min(lo, begin[i]), hi = std::max(hi, end[i]);
            for (int c0 = lo; c0 < hi; c0 += kChunk) {
              const int c1 = std::min(hi, c0 + kChunk);
              int b[kPacket], e[kPacket];
              for (int i = 0; i < kPacket; ++i) b[i] = std::max(begin[i], c0), e[i] = std::min(end[i], c1);
              im.integrator.trace_camera_block(bx, y, c0, c1, b, e, &block, &rays);
              for (int i = 0; i < kPacket; ++i)
                if (b[i] < e[i]) add(i, b[i], e[i]);
            }
          };
          PixelTotals pilot[kPacket], tot[kPacket];
          for (int i = 0; i < kPacket; ++i) begin[i] = 0, end[i] = i < lanes ? first : 0;
          render_rounds([&](int i, int b, int e) {
            im.integrator.add_samples(bx + i, y, block, b, e, 1.0, totals_only, nullptr, &rays, nullptr, nullptr, &pilot[i]);
          });
          // The paths the pilot's spread asks for (the error falls as 1 / sqrt(paths)), 10 % more; none of the
          // light in the pilot: as many as it had. Of the laser return and, where the acquisition's counts are
          // of it (RenderStageConfig), of the ambient light: the more of the two.
          // floor: a rate the counts hardly see, added to the light's mean (the ambient light's, per row)
          const auto paths_for = [&](double sum, double sq, double floor = 0.0) {
            const double mean = sum / first, se = standard_error(sum, sq, first, 1.0);
            if (!(mean > 0.0 && se > 0.0)) return double(first);
            const double r = se / (target * (mean + floor));
            return std::clamp(std::ceil(first * r * r * 1.1), double(first), double(most));
          };
          for (int i = 0; i < lanes; ++i) {
            double want = first;
            if (im.config.target_laser) want = std::max(want, paths_for(pilot[i].laser_total, pilot[i].laser_sq));
            if (im.config.target_ambient && !(ambient_floor == std::numeric_limits<double>::infinity()))
              want = std::max(want, paths_for(pilot[i].ambient_rate, pilot[i].ambient_sq, ambient_floor));
            begin[i] = first, end[i] = first + int(want);
          }
          render_rounds([&](int i, int b, int e) {
            const int x = bx + i;
            const bool own = x >= data_rect.x0 && x < data_rect.x1();
            const bool split_objects = gt && own && rect.contains(x, y);
            im.integrator.add_samples(x, y, block, b, e, 1.0, axis, acc.data() + size_t(i) * bins, &rays,
                                      split ? acc_indirect.data() + size_t(i) * bins : nullptr,
                                      split_objects ? &objects[size_t(i)] : nullptr, &tot[i]);
          });
          for (int i = 0; i < lanes; ++i) {
            const int x = bx + i, paths = end[i] - begin[i];
            if (x < data_rect.x0 || x >= data_rect.x1()) {  // not this tile's: cleared
              const PixelTotals& t = tot[i];
              for (int64_t b = t.bin_lo; b < t.bin_hi; ++b) {
                acc[size_t(i) * bins + size_t(b)] = 0.0;
                if (split) acc_indirect[size_t(i) * bins + size_t(b)] = 0.0;
              }
              objects[size_t(i)].clear();
              continue;
            }
            const double scale = 1.0 / paths;
            if (gt && rect.contains(x, y)) {
              put_object_laser(&objects[size_t(i)], rect.index(x, y), gt, scale);
              objects[size_t(i)].clear();
            }
            store(x, y, tot[i], scale, paths, standard_error(tot[i].laser_total, tot[i].laser_sq, paths, 1.0),
                  standard_error(tot[i].ambient_rate, tot[i].ambient_sq, paths, 1.0), acc.data() + size_t(i) * bins,
                  split ? acc_indirect.data() + size_t(i) * bins : nullptr);
          }
        }
      }
      add_rays(rays);
    });
  }
  // Stored as float: a light too bright for the scene's distances (a glTF point light of 1e35 cd half a metre
  // from a wall) was stored as infinity, and every output from it (counts, detections) was meaningless. The
  // first such pixel in the tile's order is named (the tile's own pixels before its halo's, outside the image).
  for (const bool own : {true, false})
    for (size_t i = 0; i < n; ++i) {
      const int x = data_rect.x0 + int(i % size_t(data_rect.width)), y = data_rect.y0 + int(i / size_t(data_rect.width));
      if (rect.contains(x, y) == own && (!std::isfinite(tile.ambient_rate[i]) || !std::isfinite(tile.ambient_se[i])))
        throw Error("render: sensor pixel (" + std::to_string(x) + ", " + std::to_string(y) + ") receives more than " +
                  "3.4e38 photons per second of ambient light, beyond what its float32 outputs hold: a glTF light "
                    "(KHR_lights_punctual intensity) or emissive material is too bright for the scene's distances");
    }
  if (stats) {
    stats->rays += tile_rays;
    for (int y = rect.y0; y < rect.y1(); ++y)
      for (int x = rect.x0; x < rect.x1(); ++x) stats->camera_hits += static_cast<uint64_t>(camera_hits[size_t(data_rect.index(x, y))]);
  }
  return tile;
}

}  // namespace spadgen::render
