// What bench_render and bench_render_rays share: the benchmark's scene and the way an image is rendered,
// so that the rays bench_render_rays records are the rays bench_render's integrator traces.
#pragma once
#include <string>

#include "core/config.h"
#include "core/tile.h"
#include "core/time_axis.h"
#include "render/renderer.h"
#include "scenes/scene.h"

namespace spadgen::bench {

struct Setup {
  scenes::Scene scene;
  RunConfig config;
  std::string source;
};

// The renderer's part of the run, with the fill factor of every row as the sensor's pixel layout gives it.
RenderStageConfig stage(const RunConfig& c);

// scenes/paper/multi_object.json at 1024 x 1000 (a similar scene built in code when the file is missing).
Setup& setup();

// Renders `region` tile by tile, as the app does (TBB over tiles of 32 x 32).
render::RenderStats render_image(const render::Renderer& r, const RunConfig& c, const TimeAxis& axis,
                                 const PixelRect& region);

}  // namespace spadgen::bench
