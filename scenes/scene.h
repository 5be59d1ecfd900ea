// The immutable scene: every triangle mesh in world space (metres), its materials, the glTF cameras and
// lights. Built once from a glTF file by load_gltf(), with the scene file's edits of its nodes and
// materials applied; render/ turns it into an Embree scene.
#pragma once
#include <glm/glm.hpp>

#include <algorithm>
#include <cstdint>
#include <limits>
#include <memory>
#include <string>
#include <vector>

#include "core/config.h"
#include "core/error.h"

namespace spadgen::scenes {

// An RGBA8 image from the glTF, as decoded by tinygltf (sRGB-encoded for base colour).
struct Texture {
  std::string name;
  int width = 0, height = 0;
  // width * height * 4 bytes, row 0 at the top (glTF uv (0,0) is the top-left); immutable and shared, so
  // that a copy of the Scene (the renderer's, centred on its camera) and textures of one image hold the
  // texels once.
  std::shared_ptr<const std::vector<uint8_t>> texels;
  const std::vector<uint8_t>& rgba() const { return *texels; }
  // Sampler wrap modes (glTF codes: 10497 repeat, 33071 clamp, 33648 mirrored repeat).
  int wrap_s = 10497, wrap_t = 10497;
};

// Below this GGX alpha (roughness^2) a surface is smooth: it reflects and refracts by Dirac lobes only.
inline constexpr float kSmoothAlpha = 1e-3f;
// From this GGX alpha on (roughness 0.158) a flat refracting face is crossed as rough by the laser's connections
// (drawn microfacet normals); below, as smooth (at 0.15 and below within 0.2 % of the rough estimate behind a
// 3 mm plate, with less noise; at 0.2 +0.5 % and +1.9 %, docs/render.md).
inline constexpr float kRoughCrossingAlpha = 0.025f;

struct Material {
  std::string name;
  glm::vec4 base_color{1, 1, 1, 1};  // pbrMetallicRoughness.baseColorFactor (linear)
  int base_color_texture = -1;       // index into Scene::textures, -1 none
  int base_color_texcoord = 0;       // TEXCOORD_n set used by it
  bool base_color_transformed = false;  // its KHR_texture_transform maps the coordinates (applied at load)
  float metallic = 1.0f;             // glTF defaults: metallic 1, roughness 1
  float roughness = 1.0f;
  glm::vec3 emissive{0, 0, 0};       // emissiveFactor times KHR_materials_emissive_strength
  bool double_sided = false;
  float transmission = 0.0f;         // KHR_materials_transmission.transmissionFactor
  float ior = 1.5f;                  // KHR_materials_ior.ior
  float thickness_m = 0.0f;          // KHR_materials_volume.thicknessFactor (0: thin-walled)
  float attenuation_distance_m = std::numeric_limits<float>::infinity();  // KHR_materials_volume
  glm::vec3 attenuation_color{1, 1, 1};                                   // KHR_materials_volume
  bool transmissive() const { return transmission > 0.0f; }
  // Diffuse only, without a Fresnel layer or a GGX lobe (metallic 0, roughness 1, no transmission, each
  // clamped to [0, 1] as the renderer takes them).
  bool lambertian() const {
    return std::clamp(metallic, 0.0f, 1.0f) == 0.0f && std::clamp(roughness, 0.0f, 1.0f) == 1.0f &&
           std::clamp(transmission, 0.0f, 1.0f) == 0.0f;
  }
  // GGX alpha = roughness^2, the roughness clamped to [0, 1] as the renderer takes it.
  float alpha() const {
    const float r = std::clamp(roughness, 0.0f, 1.0f);
    return r * r;
  }
  // A smooth surface (alpha below kSmoothAlpha): Dirac lobes only.
  bool smooth() const { return alpha() < kSmoothAlpha; }
  // A face the laser's connections cross as rough (alpha at least kRoughCrossingAlpha).
  bool crossed_as_rough() const { return alpha() >= kRoughCrossingAlpha; }
  // A medium bounded by the mesh (not thin-walled): what its triangles enclose.
  bool bounds_medium() const { return transmissive() && thickness_m > 0.0f; }
  // A volume that bends light: the laser's connections refract through it.
  bool refracting() const { return bounds_medium() && ior != 1.0f; }
  // The scene file's values of materials.<name> replace the factors, as if the glTF file had given them (a
  // transmission above 0 makes the material transmissive whether or not it declared KHR_materials_transmission).
  void apply(const MaterialEdit& e) {
    for (int k = 0; k < 3; ++k)
      if (e.base_color[k]) base_color[k] = static_cast<float>(*e.base_color[k]);
    if (e.roughness) roughness = static_cast<float>(*e.roughness);
    if (e.metallic) metallic = static_cast<float>(*e.metallic);
    if (e.transmission) transmission = static_cast<float>(*e.transmission);
    if (e.ior) ior = static_cast<float>(*e.ior);
    if (e.thickness_m) thickness_m = static_cast<float>(*e.thickness_m);
  }
};

// Mesh::offset's grid: a mesh whose vertices lie this far from the glTF's origin or farther has its positions
// measured from a point of this grid near their centre (floats 32 m from a point are 3.8 um apart at most).
inline constexpr double kMeshOffsetGridM = 64.0;

// Meshes of at most this many triangles are planar parts (plates, boxes) the renderer aims at face by face; one of
// more, with vertex normals, is curved (a sphere, a bottle: Mesh::curved), whose paths of the laser it seeks about
// its bounding box (render/integrator.cpp).
inline constexpr size_t kMaxPlanarParts = 64;

// One glTF primitive instanced by one node, flattened into world space.
struct Mesh {
  std::string name;        // "<node name>/<mesh name>/<primitive index>"
  int gltf_node = -1, gltf_mesh = -1, gltf_primitive = -1;
  // World point the positions are measured from (world = offset + position, in double): the centre of the
  // vertices' bounding box rounded to kMeshOffsetGridM (0 within 32 m of the origin), so that a scene far
  // from the glTF's origin keeps its float precision (a 2 mm plate 70 km away, where world floats are 7.8
  // mm apart, keeps its thickness).
  glm::dvec3 offset{0.0};
  std::vector<glm::vec3> positions;  // world space minus offset, metres
  std::vector<glm::vec3> normals;    // world space, unit; empty when the primitive has none
  std::vector<glm::vec2> texcoords0, texcoords1;  // empty when absent
  std::vector<glm::vec3> colors0;    // COLOR_0 (linear RGB, multiplies the base colour); empty when absent
  std::vector<uint32_t> indices;     // 3 per triangle (non-indexed primitives get 0, 1, 2, ...)
  int material = -1;                 // index into Scene::materials, -1: the glTF default material
  size_t triangle_count() const { return indices.size() / 3; }
  bool has_normals() const { return !positions.empty() && normals.size() == positions.size(); }
  bool curved() const { return triangle_count() > kMaxPlanarParts && has_normals(); }
  // Some corner's normal is not its triangle's own (the winding's) within 1e-6 in cosine: light refracts and
  // reflects at its interpolated normals, and the renderer's laser connections through it are solved on them.
  bool smooth_shaded() const {
    if (!has_normals()) return false;
    for (size_t i = 0; i + 2 < indices.size(); i += 3) {
      const uint32_t a = indices[i], b = indices[i + 1], c = indices[i + 2];
      if (a >= positions.size() || b >= positions.size() || c >= positions.size()) continue;
      const glm::vec3 n = glm::cross(positions[b] - positions[a], positions[c] - positions[a]);
      const float len = glm::length(n);
      if (!(len > 0.0f)) continue;
      for (uint32_t v : {a, b, c})
        if (glm::dot(glm::normalize(normals[v]), n / len) < 1.0f - 1e-6f) return true;
    }
    return false;
  }
};

struct Camera {
  std::string name;                  // the node's name (or the camera's when the node has none)
  std::string where;                 // the glTF camera and node, for messages ("camera 0 'c' (node 3 'cam')")
  glm::dmat4 world_from_camera{1.0}; // the node's world transform; the camera looks down its local -Z, +Y up
  double yfov_rad = 0.0;
  double aspect_ratio = 0.0;         // 0 when the glTF does not give one
};

struct Light {
  enum class Type { Point, Spot, Directional };
  std::string name;
  std::string where;                 // the glTF light and node, for messages
  Type type = Type::Point;
  glm::vec3 color{1, 1, 1};
  double intensity = 1.0;            // KHR_lights_punctual: candela (point, spot) or lux (directional)
  double range = 0.0;                // 0: infinite
  double inner_cone_rad = 0.0, outer_cone_rad = 0.7853981633974483;
  glm::dvec3 position{0, 0, 0};      // world
  glm::dvec3 direction{0, 0, -1};    // world, unit: the node's local -Z
};

// A glTF node, as `spadgen info` lists them (the scene file's `nodes` section names them).
struct Node {
  std::string name;
  int parent = -1;                   // glTF index of the parent node, -1 for a root
  bool loaded = false;               // part of the loaded glTF scene (a node of another glTF scene is not)
  glm::dmat4 world{1.0};             // world transform, edits applied (identity when not loaded)
};

struct Scene {
  std::string source;                // path of the glTF file
  std::vector<Node> nodes;           // every glTF node, by glTF index
  std::vector<Mesh> meshes;
  std::vector<Material> materials;
  std::vector<Texture> textures;
  std::vector<Camera> cameras;
  std::vector<std::string> orthographic_cameras;  // their names (node's, else camera's): skipped, named if chosen
  std::vector<Light> lights;
  std::vector<std::string> warnings; // what spadgen does not use, once per element (also printed)

  // Whether some mesh uses material i (a glTF may define materials no mesh uses: the renderer's choices,
  // and what a run reports of its model, depend on the used ones only).
  bool material_used(size_t i) const {
    for (const Mesh& m : meshes)
      if (m.material >= 0 && static_cast<size_t>(m.material) == i) return true;
    return false;
  }
  bool has_transmission() const {
    for (size_t i = 0; i < materials.size(); ++i)
      if (materials[i].transmissive() && material_used(i)) return true;
    return false;
  }
  size_t triangle_count() const {
    size_t n = 0;
    for (const Mesh& m : meshes) n += m.triangle_count();
    return n;
  }
  // The camera or light of that name; nullptr when none has it. Two of one name are an error naming both
  // (the first was taken: a scene file could not tell which it chose). what: the scene-file key, for it.
  const Camera* find_camera(const std::string& name, const char* what = "camera.gltf_camera") const {
    return find_named(cameras, name, what, "perspective cameras");
  }
  const Light* find_light(const std::string& name, const char* what = "laser.gltf_light") const {
    return find_named(lights, name, what, "KHR_lights_punctual lights");
  }
  template <class T>
  const T* find_named(const std::vector<T>& list, const std::string& name, const char* what, const char* kind) const {
    const T* found = nullptr;
    std::string all;
    int n = 0;
    for (const T& x : list)
      if (x.name == name) {
        if (!found) found = &x;
        all += (n++ ? ", " : "") + x.where;
      }
    if (n > 1)
      throw Error(std::string(what) + ": " + std::to_string(n) + " " + kind + " are named '" + name + "' in " + source + " (" +
                  all + "); expected one: rename them in the glTF so that the name picks one");
    return found;
  }
  // For a camera or light not found by name: "" or, when a node of that name is in the file but not in the
  // loaded glTF scene (whose cameras and lights are the only ones read), a sentence that says so.
  std::string not_loaded_note(const std::string& name) const {
    for (const Node& n : nodes)
      if (n.name == name && !n.loaded)
        return "; the file has a node '" + name + "', but it is not in the glTF scene loaded (gltf_scene: \"\" is the file's "
               "default scene), whose cameras and lights are the only ones read";
    return "";
  }
};

// An object of the ground truth: a glTF node that has a mesh, all its primitives (Scene::meshes) together,
// so that a plate's two faces are one object. Ids are dense, 0..M-1 in glTF node order; a mesh built
// without a node (gltf_node -1, as tests build scenes in code) is an object of its own, after those.
struct Object {
  int id = 0;
  std::string name;          // the glTF node's name (the scene file's nodes.NAME keys), "" for a mesh without node
  int node = -1;             // glTF node index, -1 for a mesh without node
  std::vector<int> meshes;   // indices into Scene::meshes (the mesh_id of the ground truth), ascending
};

struct Objects {
  std::vector<Object> list;      // by id
  std::vector<int> mesh_object;  // [mesh index]: its object's id
};
Objects objects_of(const Scene& scene);

// Loads a .gltf (external or embedded buffers) or .glb file. scene_name "" picks the file's default scene
// (or scene 0). Throws spadgen::Error naming the file and the glTF element on any broken input.
//
// `edits` (the scene file's nodes and materials sections, RunConfig::edits) name glTF nodes and materials;
// a name that no element or several elements carry is an error naming the scene-file key (/nodes/Sphre),
// the glTF file and the names it has. A node's edit replaces components of its local transform before world
// transforms are composed, so that its subtree (meshes, cameras, lights) follows; a node given as a matrix
// is decomposed into translation, rotation and scale first (an error when it has shear). A material's edit
// replaces its factors. An edit of a material no loaded mesh uses, or of a node outside the loaded glTF
// scene, is a warning (it changes nothing). docs/scene-file.md, "Varying the glTF scene".
Scene load_gltf(const std::string& path, const std::string& scene_name = "", const SceneEdits& edits = {});

// load_gltf's error for an edit of a node or material the glTF does not have, or has several of: its
// message starts with the edit's pointer ("/nodes/NAME: "); section ("nodes", "materials") and name say which
// edit, for a caller to name the key that gave it (a --set key, a dataset's key).
struct EditError : Error {
  EditError(std::string edit_section, std::string edit_name, const std::string& message)
      : Error(message), section(std::move(edit_section)), name(std::move(edit_name)) {}
  std::string section, name;
};

// The files a glTF file reads besides itself: its buffers' and images' URIs that are not data: URIs,
// resolved against its folder as the loader resolves them (percent-decoded, else as written), in the order
// it lists them. Throws spadgen::Error when the file is not glTF (as load_gltf does).
std::vector<std::string> gltf_external_files(const std::string& path);

// The same from the file's bytes (.gltf or .glb, told apart by content): `path` names the file in messages
// and its folder is where external buffers and images are looked for. The fuzzing harnesses call it.
Scene parse_gltf(const std::string& bytes, const std::string& path, const std::string& scene_name = "",
                 const SceneEdits& edits = {});

// A human-readable summary for `spadgen info`: nodes (the names the scene file's nodes section takes),
// meshes, triangles, materials with their extensions, cameras, lights, warnings.
std::string summarize(const Scene& scene);

}  // namespace spadgen::scenes
