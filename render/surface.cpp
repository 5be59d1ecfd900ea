#include "surface.h"

#include <algorithm>
#include <cmath>

namespace spadgen::render {
namespace {

Spec to_spec(const glm::vec3& rgb, const glm::vec3& w_laser, const glm::vec3& w_ambient) {
  return {glm::dot(rgb, w_laser), glm::dot(rgb, w_ambient)};
}

int wrap(int i, int n, int mode) {
  switch (mode) {
    case 33071:  // clamp to edge
      return std::clamp(i, 0, n - 1);
    case 33648: {  // mirrored repeat
      const int period = 2 * n;
      int k = i % period;
      if (k < 0) k += period;
      return k < n ? k : period - 1 - k;
    }
    default: {  // repeat
      int k = i % n;
      return k < 0 ? k + n : k;
    }
  }
}

}  // namespace

Shading::Shading(const scenes::Scene& scene, double laser_wavelength_m, const glm::vec3& ambient_rgb_weights,
                 double ambient_photometric)
    : scene_(scene), w_laser_(rgb_weights_at(laser_wavelength_m)), w_ambient_(ambient_rgb_weights) {
  for (int i = 0; i < 256; ++i) {
    const double c = i / 255.0;
    srgb_[i] = static_cast<float>(c <= 0.04045 ? c / 12.92 : std::pow((c + 0.055) / 1.055, 2.4));
  }
  auto resolve = [&](const scenes::Material& m) {
    ResolvedMaterial r;
    MaterialPoint& p = r.point;
    r.base_rgb = glm::vec3(m.base_color);
    p.base = to_spec(r.base_rgb, w_laser_, w_ambient_);
    p.metallic = std::clamp(m.metallic, 0.0f, 1.0f);
    const float roughness = std::clamp(m.roughness, 0.0f, 1.0f);
    p.alpha = roughness * roughness;
    p.transmission = std::clamp(m.transmission, 0.0f, 1.0f);
    p.ior = m.ior > 0.0f ? m.ior : 1.5f;
    p.thin_walled = !(m.thickness_m > 0.0f);
    p.lambertian = m.lambertian();
    p.emission = to_spec(m.emissive, w_laser_, w_ambient_) * static_cast<float>(ambient_photometric);
    p.emission.x = 0.0f;  // emissive surfaces are ambient light; the laser is the only pulsed source
    if (p.emission.y > 0.0f) has_emission_ = true;
    r.texture = (m.base_color_texture >= 0 && size_t(m.base_color_texture) < scene.textures.size() &&
                 scene.textures[size_t(m.base_color_texture)].width > 0)
                    ? m.base_color_texture
                    : -1;
    r.texcoord = m.base_color_texcoord;
    r.volume = m.bounds_medium();
    // glTF: attenuationColor is the colour white light becomes after attenuationDistance inside.
    if (r.volume && std::isfinite(m.attenuation_distance_m) && m.attenuation_distance_m > 0.0f) {
      const Spec c = glm::clamp(to_spec(m.attenuation_color, w_laser_, w_ambient_), Spec(1e-30f), Spec(1.0f));
      r.sigma = -glm::log(c) / m.attenuation_distance_m;
      r.absorbing = r.sigma.x > 0.0f || r.sigma.y > 0.0f;
    }
    return r;
  };
  materials_.reserve(scene.materials.size());
  for (const scenes::Material& m : scene.materials) materials_.push_back(resolve(m));
  default_ = resolve(scenes::Material{});
  triangles_.resize(scene.meshes.size());
  triangle_normals_.resize(scene.meshes.size());
  for (size_t m = 0; m < scene.meshes.size(); ++m) {
    const scenes::Mesh& mesh = scene.meshes[m];
    const size_t nv = mesh.positions.size();
    const bool normals = mesh.has_normals();
    std::vector<TriangleGeometry>& tg = triangles_[m];
    tg.resize(mesh.indices.size() / 3);
    if (normals) triangle_normals_[m].resize(tg.size());
    for (size_t t = 0; t < tg.size(); ++t) {
      const uint32_t* idx = &mesh.indices[3 * t];
      if (idx[0] >= nv || idx[1] >= nv || idx[2] >= nv) continue;  // EmbreeScene rejects such a mesh
      TriangleGeometry& g = tg[t];
      g.p0 = mesh.positions[idx[0]], g.p1 = mesh.positions[idx[1]], g.p2 = mesh.positions[idx[2]];
      const glm::vec3 n = glm::cross(g.p1 - g.p0, g.p2 - g.p0);
      const float len = glm::length(n);
      g.ng = len > 0.0f ? n / len : glm::vec3(0, 0, 1);
      if (normals) triangle_normals_[m][t] = {mesh.normals[idx[0]], mesh.normals[idx[1]], mesh.normals[idx[2]]};
    }
  }
}

Surface Shading::geometric(const RayHit& hit) const {
  const TriangleGeometry& g = triangles_[hit.mesh][hit.triangle];
  Surface s;
  s.p = (1.0f - hit.u - hit.v) * g.p0 + hit.u * g.p1 + hit.v * g.p2;
  s.ng = g.ng;
  s.ns = s.ng;
  s.mesh = static_cast<int>(hit.mesh);
  const int material = scene_.meshes[hit.mesh].material;
  s.material = (material >= 0 && size_t(material) < materials_.size()) ? material : -1;
  return s;
}

Surface Shading::surface(const RayHit& hit) const {
  Surface s = geometric(hit);
  const std::vector<TriangleNormals>& tn = triangle_normals_[hit.mesh];
  if (!tn.empty()) {
    const TriangleNormals& n = tn[hit.triangle];
    const glm::vec3 ns = (1.0f - hit.u - hit.v) * n.n0 + hit.u * n.n1 + hit.v * n.n2;
    const float l = glm::length(ns);
    if (l > 1e-6f) s.ns = ns / l;
  }
  return s;
}

bool Shading::face(uint32_t mesh, uint32_t triangle, PlanarFace* out) const {
  const TriangleGeometry& g = triangles_[mesh][triangle];
  const glm::dvec3 p0(g.p0), e1 = glm::dvec3(g.p1) - p0, e2 = glm::dvec3(g.p2) - p0;
  const double a = glm::dot(e1, e1), b = glm::dot(e1, e2), c = glm::dot(e2, e2), det = a * c - b * b;
  if (!(det > 1e-12 * a * c)) return false;
  *out = PlanarFace{p0, glm::normalize(glm::cross(e1, e2))};
  out->dual[0] = (c * e1 - b * e2) / det;
  out->dual[1] = (a * e2 - b * e1) / det;
  out->mesh = mesh, out->triangle = triangle;
  const std::vector<TriangleNormals>& tn = triangle_normals_[mesh];
  if (!tn.empty()) {
    const TriangleNormals& n = tn[triangle];
    const glm::dvec3 n0(n.n0);
    out->shaded = true;
    out->m = n0;
    // m(y) = n0 + (n1 - n0) u(y) + (n2 - n0) v(y), u and v the barycentrics
    out->grad = glm::outerProduct(glm::dvec3(n.n1) - n0, out->dual[0]) + glm::outerProduct(glm::dvec3(n.n2) - n0, out->dual[1]);
  }
  return true;
}

MaterialPoint Shading::material_at(const Surface& s, const RayHit& hit) const {
  const ResolvedMaterial& r = material(s.material);
  MaterialPoint p = r.point;
  const scenes::Mesh& mesh = scene_.meshes[size_t(s.mesh)];
  if (r.texture < 0 && mesh.colors0.empty()) return p;
  const uint32_t* idx = &mesh.indices[3 * size_t(hit.triangle)];
  const float w0 = 1.0f - hit.u - hit.v;
  // glTF: base colour = factor x texture x COLOR_0, channel by channel, then reduced to the laser's and the
  // ambient light's bands (the product of reductions is not the reduction of the product: a red factor on a
  // green texture reflected ambient light).
  glm::vec3 rgb = r.base_rgb;
  if (r.texture >= 0) {
    const std::vector<glm::vec2>& tc = r.texcoord == 1 ? mesh.texcoords1 : mesh.texcoords0;
    if (tc.size() == mesh.positions.size())
      rgb *= texture_rgb(r.texture, w0 * tc[idx[0]] + hit.u * tc[idx[1]] + hit.v * tc[idx[2]]);
  }
  if (mesh.colors0.size() == mesh.positions.size())
    rgb *= w0 * mesh.colors0[idx[0]] + hit.u * mesh.colors0[idx[1]] + hit.v * mesh.colors0[idx[2]];
  p.base = to_spec(rgb, w_laser_, w_ambient_);
  return p;
}

// Bilinear filtering of the decoded (linear) texels: decoding after filtering would darken edges.
glm::vec3 Shading::texture_rgb(int texture, const glm::vec2& uv) const {
  const scenes::Texture& t = scene_.textures[size_t(texture)];
  const float x = uv.x * static_cast<float>(t.width) - 0.5f;
  const float y = uv.y * static_cast<float>(t.height) - 0.5f;
  const float fx = std::floor(x), fy = std::floor(y);
  const float ax = x - fx, ay = y - fy;
  const int x0 = static_cast<int>(fx), y0 = static_cast<int>(fy);
  auto texel = [&](int i, int j) {
    const int xi = wrap(i, t.width, t.wrap_s), yj = wrap(j, t.height, t.wrap_t);
    const uint8_t* px = &t.rgba()[(size_t(yj) * size_t(t.width) + size_t(xi)) * 4];
    return glm::vec3(srgb_[px[0]], srgb_[px[1]], srgb_[px[2]]);
  };
  return (1 - ay) * ((1 - ax) * texel(x0, y0) + ax * texel(x0 + 1, y0)) +
         ay * ((1 - ax) * texel(x0, y0 + 1) + ax * texel(x0 + 1, y0 + 1));
}

}  // namespace spadgen::render
