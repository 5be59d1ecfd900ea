// glTF 2.0 -> Scene. tinygltf parses the JSON, buffers and images; everything it leaves unchecked
// (accessor and buffer-view bounds, index ranges, node cycles, camera and light parameters) is
// validated here before a byte is read, so a broken file ends in a spadgen::Error naming the file and
// the glTF element, never in a crash or a silently wrong scene.
#include <nlohmann/json.hpp>
#include <tiny_gltf.h>

#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtc/type_ptr.hpp>

#include <algorithm>
#include <array>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iomanip>
#include <limits>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "core/error.h"
#include "scenes/image_decode.h"
#include "scenes/input.h"
#include "scenes/key_path.h"
#include "scenes/scene.h"

namespace spadgen::scenes {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Limits that keep every derived quantity finite and meaningful in the renderer (docs/scenes.md, "Limits").
// World coordinates of vertices, cameras and lights: Embree traces in float and asserts on ray origins
// beyond about 1.8e18; at 1e9 m a float is already 64 m coarse.
constexpr double kMaxWorldCoordinate = 1e9;
// Texture coordinates: beyond 4096 a float no longer resolves a texel of a 4096-wide texture, and the
// texel index (coordinate times width) must stay an int.
constexpr double kMaxTexcoord = 4096.0;
// Emitted luminance, emissiveFactor times KHR_materials_emissive_strength, in nits: 600 times the sun's
// disc (1.6e9 nits). Photon radiances from it stay finite in float.
constexpr double kMaxEmissiveNits = 1e12;
// A node given as a matrix is decomposed into translation, rotation and scale when the scene file edits it.
// Recomposed, its 3 x 3 part must come back to this fraction of its largest entry, or it shears (which
// glTF does not allow). Exporters write matrices in float, whose rotations are orthonormal to about 1e-7:
// those decompose; a shear large enough to see does not.
constexpr double kDecomposeTolerance = 1e-6;

// Extensions whose content spadgen reads. Any other extension is reported once as unused, and is an
// error when the file lists it in extensionsRequired.
const std::set<std::string> kSupportedExtensions = {
    "KHR_materials_transmission", "KHR_materials_ior",      "KHR_materials_volume",
    "KHR_materials_emissive_strength", "KHR_lights_punctual", "KHR_mesh_quantization", "KHR_texture_transform",
};

std::string quoted(const std::string& s) { return "'" + s + "'"; }

// Numbers in messages as a person writes them ("0.5", "1e+308"), not std::to_string's "0.500000": the
// shortest of 6 to 17 digits that reads back as v (as a float, when v is one: accessors' values are), so a
// refused value is told from its bound (1.0000001, not 1).
std::string num(double v) {
  const bool is_float = std::isfinite(v) && std::fabs(v) <= std::numeric_limits<float>::max() &&
                        static_cast<double>(static_cast<float>(v)) == v;
  std::string out;
  for (int digits = 6; digits <= 17; ++digits) {
    std::ostringstream s;
    s << std::setprecision(digits) << v;
    out = s.str();
    const double back = std::strtod(out.c_str(), nullptr);
    if (is_float ? static_cast<float>(back) == static_cast<float>(v) : back == v) break;
  }
  return out;
}

// "mesh 2 'Cube'": the index always (names need not be unique), the name when there is one.
// A count as digits when it is whole (1000000000000, not 1e+12).
std::string num_whole(double v) {
  return v == std::floor(v) && std::fabs(v) < 9e15 ? std::to_string(static_cast<long long>(v)) : num(v);
}

std::string label(const char* kind, size_t index, const std::string& name) {
  std::string s = std::string(kind) + " " + std::to_string(index);
  if (!name.empty()) s += " " + quoted(name);
  return s;
}

const char* mode_name(int mode) {
  switch (mode) {
    case TINYGLTF_MODE_POINTS: return "POINTS";
    case TINYGLTF_MODE_LINE: return "LINES";
    case TINYGLTF_MODE_LINE_LOOP: return "LINE_LOOP";
    case TINYGLTF_MODE_LINE_STRIP: return "LINE_STRIP";
    case TINYGLTF_MODE_TRIANGLES: return "TRIANGLES";
    case TINYGLTF_MODE_TRIANGLE_STRIP: return "TRIANGLE_STRIP";
    case TINYGLTF_MODE_TRIANGLE_FAN: return "TRIANGLE_FAN";
    default: return "unknown";
  }
}

size_t component_size(int component_type) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return 1;
    case TINYGLTF_COMPONENT_TYPE_SHORT:
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return 2;
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT:
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return 4;
    default: return 0;  // not a glTF 2.0 accessor component type
  }
}

std::string component_name(int component_type) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: return "BYTE";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: return "UNSIGNED_BYTE";
    case TINYGLTF_COMPONENT_TYPE_SHORT: return "SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: return "UNSIGNED_SHORT";
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: return "UNSIGNED_INT";
    case TINYGLTF_COMPONENT_TYPE_FLOAT: return "FLOAT";
    case 5124: return "INT (5124, which glTF 2.0 does not allow)";
    default: return std::to_string(component_type) + " (no glTF 2.0 component type)";
  }
}

int type_components(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return 1;
    case TINYGLTF_TYPE_VEC2: return 2;
    case TINYGLTF_TYPE_VEC3: return 3;
    case TINYGLTF_TYPE_VEC4: return 4;
    case TINYGLTF_TYPE_MAT2: return 4;
    case TINYGLTF_TYPE_MAT3: return 9;
    case TINYGLTF_TYPE_MAT4: return 16;
    default: return 0;
  }
}

const char* type_name(int type) {
  switch (type) {
    case TINYGLTF_TYPE_SCALAR: return "SCALAR";
    case TINYGLTF_TYPE_VEC2: return "VEC2";
    case TINYGLTF_TYPE_VEC3: return "VEC3";
    case TINYGLTF_TYPE_VEC4: return "VEC4";
    case TINYGLTF_TYPE_MAT2: return "MAT2";
    case TINYGLTF_TYPE_MAT3: return "MAT3";
    case TINYGLTF_TYPE_MAT4: return "MAT4";
    default: return "invalid";
  }
}

// Reads one component at p (which need not be aligned) as a double, with the glTF normalisation rules.
double read_component(const unsigned char* p, int component_type, bool normalized) {
  switch (component_type) {
    case TINYGLTF_COMPONENT_TYPE_BYTE: {
      int8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? std::max(v / 127.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE: {
      uint8_t v;
      std::memcpy(&v, p, 1);
      return normalized ? v / 255.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_SHORT: {
      int16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? std::max(v / 32767.0, -1.0) : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT: {
      uint16_t v;
      std::memcpy(&v, p, 2);
      return normalized ? v / 65535.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT: {
      uint32_t v;
      std::memcpy(&v, p, 4);
      return normalized ? v / 4294967295.0 : v;
    }
    case TINYGLTF_COMPONENT_TYPE_FLOAT: {
      float v;
      std::memcpy(&v, p, 4);
      return v;
    }
    default: return 0.0;
  }
}

// The mimeType of a texture extension's image (KHR_texture_basisu's KTX2, EXT_texture_webp's WebP), by its
// bytes, or by its mimeType when the bytes are neither PNG nor JPEG (the bytes decide: a PNG labelled
// image/webp is a PNG); "" for any other image.
std::string extension_image_type(const unsigned char* bytes, size_t size, const std::string& mime) {
  static constexpr unsigned char kKtx2[8] = {0xab, 'K', 'T', 'X', ' ', '2', '0', 0xbb};
  if (size >= 8 && std::memcmp(bytes, kKtx2, 8) == 0) return "image/ktx2";
  if (size >= 12 && std::memcmp(bytes, "RIFF", 4) == 0 && std::memcmp(bytes + 8, "WEBP", 4) == 0) return "image/webp";
  if (is_png_or_jpeg(bytes, size)) return "";
  return mime == "image/ktx2" || mime == "image/webp" ? mime : "";
}

// image/bufferView bounds are not checked by tinygltf 2.7 before it hands the bytes to the image
// decoder; this loader checks them first, against the model tinygltf is filling.
bool load_image_checked(tinygltf::Image* image, const int image_index, std::string* err, std::string* warn,
                        int req_width, int req_height, const unsigned char* bytes, int size, void* user) {
  const auto* model = static_cast<const tinygltf::Model*>(user);
  if (image->bufferView >= 0) {
    const auto v = static_cast<size_t>(image->bufferView);
    bool ok = v < model->bufferViews.size();
    if (ok) {
      const tinygltf::BufferView& view = model->bufferViews[v];
      ok = view.buffer >= 0 && static_cast<size_t>(view.buffer) < model->buffers.size() &&
           view.byteOffset <= model->buffers[static_cast<size_t>(view.buffer)].data.size() &&
           view.byteLength <= model->buffers[static_cast<size_t>(view.buffer)].data.size() - view.byteOffset;
    }
    if (!ok) {
      if (err)
        *err += "image " + std::to_string(image_index) + ": bufferView " + std::to_string(image->bufferView) +
                " does not exist or lies past the end of its buffer\n";
      return false;
    }
  }
  // Decoded here (image_decode.h), not by tinygltf's stb_image: its PNG decoder allocates what a chunk's
  // length claims (2 GB for a 38-byte file) and its JPEG decoder writes past a Huffman table on a crafted
  // one (both found by fuzzing it).
  (void)req_width, (void)req_height;
  const std::string who = label("image", static_cast<size_t>(image_index), image->name);
  // A texture extension's image is left undecoded (as_is marks it, mimeType says which): textures read
  // their PNG or JPEG source, the extensions' fallback; one whose source it is, is refused (Loader::texture).
  // It failed the whole file, also when every texture had its fallback.
  if (const std::string type = extension_image_type(bytes, size > 0 ? static_cast<size_t>(size) : 0, image->mimeType);
      !type.empty()) {
    image->as_is = true;
    image->mimeType = type;
    return true;
  }
  DecodedImage decoded;
  std::string warning;
  const std::string problem =
      decode_image(bytes, size > 0 ? static_cast<size_t>(size) : 0, &decoded, &warning);
  if (!problem.empty()) {
    if (err) *err += who + ": " + problem + "\n";
    return false;
  }
  if (!warning.empty() && warn) *warn += who + ": " + warning + "\n";
  image->width = decoded.width;
  image->height = decoded.height;
  image->component = 4;
  image->bits = 8;
  image->pixel_type = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE;
  image->image = std::move(decoded.rgba);
  return true;
}

// A node's local transform as glTF's translation, rotation and scale.
struct Trs {
  glm::dvec3 translation{0.0};
  glm::dquat rotation{1.0, 0.0, 0.0, 0.0};  // w, x, y, z
  glm::dvec3 scale{1.0};
};

// R = Rz(a.z) * Ry(a.y) * Rx(a.x), acting on column vectors: about X first, then Y, then Z, all about the
// parent's fixed axes (Blender's XYZ Euler mode).
glm::dmat3 euler_xyz(const glm::dvec3& a) {
  const double cx = std::cos(a.x), sx = std::sin(a.x), cy = std::cos(a.y), sy = std::sin(a.y);
  const double cz = std::cos(a.z), sz = std::sin(a.z);
  glm::dmat3 r;  // glm: r[column][row]
  r[0] = {cy * cz, cy * sz, -sy};
  r[1] = {sx * sy * cz - cx * sz, sx * sy * sz + cx * cz, sx * cy};
  r[2] = {cx * sy * cz + sx * sz, cx * sy * sz - sx * cz, cx * cy};
  return r;
}

// The angles of euler_xyz that give the rotation r: y in [-pi/2, pi/2], x and z in (-pi, pi]. In gimbal
// lock (y = +-pi/2, where x and z turn about the same axis) z is 0.
glm::dvec3 euler_xyz_of(const glm::dmat3& r) {
  const double cy = std::hypot(r[0][0], r[0][1]);
  const double y = std::atan2(-r[0][2], cy);
  if (cy > 1e-12) return {std::atan2(r[1][2], r[2][2]), y, std::atan2(r[0][1], r[0][0])};
  return {std::atan2(-r[2][1], r[1][1]), y, 0.0};
}

class Loader {
 public:
  // image_files: why an image's file could not be read, by image (tinygltf's words, said where a texture uses it)
  Loader(std::string path, tinygltf::Model& model, const SceneEdits& edits, Scene& scene, std::map<int, std::string> image_files = {})
      : path_(std::move(path)), m_(model), images_(model.images), edits_(edits), scene_(scene), image_files_(std::move(image_files)) {}

  void load(const std::string& scene_name);

 private:
  [[noreturn]] void fail(const std::string& element, const std::string& what) const {
    throw Error(path_ + ": " + element + ": " + what);
  }
  void warn(const std::string& message) {
    if (warned_.insert(message).second) scene_.warnings.push_back(message);
  }

  void check_extensions();
  void check_unused_features();
  std::vector<int> pick_roots(const std::string& scene_name);
  void check_hierarchy();
  void visit(int root, const glm::dmat4& root_world);
  void visit_one(int node, const glm::dmat4& parent_world, std::vector<std::pair<int, glm::dmat4>>& stack);
  void check_world(const glm::dvec3& p, const std::string& who, const std::string& what) const;
  glm::dmat4 local_transform(size_t node) const;
  glm::dmat4 world_of(size_t node) const;  // the node's parents' transforms and its own, from its root
  void check_matrix(size_t node);
  // Per vertex of a skinned primitive: sum over its joints of weight x (joint's world x inverse bind).
  std::vector<glm::dmat4> skin_matrices(size_t node, const tinygltf::Primitive& p, size_t vertices, const std::string& who);
  // Refuses accessor `accessor` of vertex attribute `attribute` (POSITION, NORMAL, TEXCOORD_n, COLOR_0, JOINTS_n,
  // WEIGHTS_n; `morph` for a morph target's) unless glTF 2.0 allows its component type there.
  void check_component(int accessor, const std::string& who, const std::string& attribute, bool morph) const;
  void resolve_edits();
  size_t named(const char* kind, const char* section, const std::vector<std::string>& names, const std::string& name) const;
  Trs decompose(size_t node, const glm::dmat4& m) const;
  glm::dmat4 edited(const NodeEdit& e, const Trs& base) const;
  void warn_unused_edits();
  void check_volumes();

  void load_materials();
  int texture(int gltf_texture, const std::string& user);
  void load_primitive(size_t node, size_t mesh, size_t prim, const glm::dmat4& world);
  void load_camera(size_t node, const glm::dmat4& world);
  void load_light(size_t node, const glm::dmat4& world);
  std::string object_name(size_t node) const;
  std::string chosen_name(size_t node, const std::string& own) const;

  // Reads accessor `index` for `user` (the element that references it, for messages) as doubles,
  // count * components, after checking every byte it touches lies inside its view and buffer.
  std::vector<double> read_accessor(int index, const std::string& user, std::initializer_list<int> types,
                                    size_t* count, int* components);
  void check_view_range(int view_index, size_t offset, size_t bytes, const std::string& who);

  double number(const tinygltf::Value& object, const char* key, double fallback, const std::string& who) const;
  glm::dvec3 vec3(const std::vector<double>& v, glm::dvec3 fallback, const std::string& who, const char* what) const;

  std::string path_;
  const tinygltf::Model& m_;
  std::vector<tinygltf::Image>& images_;  // m_.images: the decoded images move into the scene
  const SceneEdits& edits_;
  Scene& scene_;
  std::map<int, std::string> image_files_;  // why an image's file could not be read, by image
  std::vector<const NodeEdit*> node_edit_;          // per glTF node: the scene file's edit, or null
  std::vector<const MaterialEdit*> material_edit_;  // per glTF material
  std::set<std::string> warned_;
  std::map<int, int> texture_of_gltf_;   // glTF texture index -> Scene::textures index
  // glTF material -> its baseColorTexture's KHR_texture_transform as u' = m0 u + m1 v + m2, v' = m3 u + m4 v + m5
  std::map<int, std::array<double, 6>> uv_transform_;
  std::map<int, std::shared_ptr<const std::vector<uint8_t>>> texels_of_image_;  // glTF image -> its decoded texels
  std::vector<int> parent_;              // per node, -1 for roots
  mutable std::vector<glm::dmat4> world_;  // per node, its world transform once world_of computed it
  mutable std::vector<char> world_known_;
};

std::string node_label(const tinygltf::Model& m, size_t i) { return label("node", i, m.nodes[i].name); }

// Buffers are named by their file when they have no name; a data: URI would only be noise.
std::string buffer_label(size_t i, const tinygltf::Buffer& b) {
  if (!b.name.empty() || b.uri.rfind("data:", 0) == 0) return label("buffer", i, b.name);
  return label("buffer", i, b.uri);
}

void Loader::check_extensions() {
  std::set<std::string> unused;
  for (const std::string& e : m_.extensionsUsed)
    if (!kSupportedExtensions.count(e)) unused.insert(e);
  // Extensions present on elements but missing from extensionsUsed are still reported.
  for (const tinygltf::Material& mat : m_.materials)
    for (const auto& e : mat.extensions)
      if (!kSupportedExtensions.count(e.first)) unused.insert(e.first);
  for (const tinygltf::Node& n : m_.nodes)
    for (const auto& e : n.extensions)
      if (!kSupportedExtensions.count(e.first)) unused.insert(e.first);
  for (const std::string& e : m_.extensionsRequired)
    if (!kSupportedExtensions.count(e))
      throw Error(path_ + ": extension " + quoted(e) +
                  " is listed in extensionsRequired but spadgen does not support it");
  for (const std::string& e : unused)
    warn("extension " + quoted(e) + " is not used by spadgen; ignored");
}

void Loader::check_unused_features() {
  for (size_t i = 0; i < m_.animations.size(); ++i)
    warn(label("animation", i, m_.animations[i].name) +
         ": animations are not used by spadgen; the scene is loaded in its rest pose");
}

std::vector<int> Loader::pick_roots(const std::string& scene_name) {
  if (m_.scenes.empty()) {
    if (!scene_name.empty())
      throw EditError("gltf_scene", scene_name, "/gltf_scene: the glTF file " + path_ + " has no scene named " +
                                                    quoted(scenes::printable(scene_name)) + ": it has no scenes");
    // A default scene that does not exist is refused, with scenes or without (without, it was loaded as the
    // root nodes, unsaid: an auditor's find)
    if (m_.defaultScene >= 0)
      throw Error(path_ + ": scene " + std::to_string(m_.defaultScene) + " (the default scene) does not exist; the file has "
                  "no scenes");
    // Without scenes the specification leaves the file's content unspecified: load every root node
    // rather than nothing, and say so.
    if (!m_.nodes.empty()) warn("the file has no scenes; every root node is loaded");
    std::vector<int> roots;
    for (size_t i = 0; i < m_.nodes.size(); ++i)
      if (parent_[i] < 0) roots.push_back(static_cast<int>(i));
    return roots;
  }
  size_t chosen = 0;
  if (!scene_name.empty()) {
    auto it = std::find_if(m_.scenes.begin(), m_.scenes.end(),
                           [&](const tinygltf::Scene& s) { return s.name == scene_name; });
    if (it == m_.scenes.end()) {
      std::string names;
      for (size_t i = 0; i < m_.scenes.size(); ++i)
        names += (i ? ", " : "") + (m_.scenes[i].name.empty() ? "(unnamed scene " + std::to_string(i) + ")"
                                                              : quoted(m_.scenes[i].name));
      throw EditError("gltf_scene", scene_name, "/gltf_scene: the glTF file " + path_ + " has no scene named " +
                                                    quoted(scenes::printable(scene_name)) + "; its scenes are: " + names);
    }
    chosen = static_cast<size_t>(it - m_.scenes.begin());
    // Two scenes of that name: which one is meant cannot be told (the first was taken, silently; two nodes,
    // materials or cameras of one name are refused as well)
    if (const auto again = std::find_if(it + 1, m_.scenes.end(), [&](const tinygltf::Scene& o) { return o.name == scene_name; });
        again != m_.scenes.end())
      throw EditError("gltf_scene", scene_name, "/gltf_scene: the glTF file " + path_ + " has two scenes named " +
                                                    quoted(scenes::printable(scene_name)) + " (scenes " + std::to_string(chosen) + " and " +
                                                    std::to_string(again - m_.scenes.begin()) + "); rename one in the glTF");
  } else if (m_.defaultScene >= 0) {
    if (static_cast<size_t>(m_.defaultScene) >= m_.scenes.size())
      throw Error(path_ + ": scene " + std::to_string(m_.defaultScene) + " (the default scene) does not exist; the file has " +
                  std::to_string(m_.scenes.size()) + " scenes");
    chosen = static_cast<size_t>(m_.defaultScene);
  }
  const tinygltf::Scene& s = m_.scenes[chosen];
  std::set<int> listed;
  for (int n : s.nodes)
    if (!listed.insert(n).second)
      fail(label("scene", chosen, s.name), "lists node " + std::to_string(n) + " twice; a scene's nodes are unique "
                                           "(glTF 2.0 scenes[].nodes, uniqueItems): its meshes would be loaded twice");
    else if (n < 0 || static_cast<size_t>(n) >= m_.nodes.size())
      fail(label("scene", chosen, s.name), "node " + std::to_string(n) + " does not exist (the file has " +
                                               std::to_string(m_.nodes.size()) + " nodes)");
    else if (parent_[static_cast<size_t>(n)] >= 0)
      fail(label("scene", chosen, s.name), "lists " + node_label(m_, static_cast<size_t>(n)) + ", a child of " +
                                               node_label(m_, static_cast<size_t>(parent_[static_cast<size_t>(n)])) +
                                               "; a scene lists root nodes only (glTF 2.0 scenes[].nodes): its mesh would "
                                               "be loaded without its parent's transform, or twice");
  return s.nodes;
}

void Loader::check_hierarchy() {
  parent_.assign(m_.nodes.size(), -1);
  for (size_t i = 0; i < m_.nodes.size(); ++i) {
    for (int c : m_.nodes[i].children) {
      if (c < 0 || static_cast<size_t>(c) >= m_.nodes.size())
        fail(node_label(m_, i), "child node " + std::to_string(c) + " does not exist (the file has " +
                                    std::to_string(m_.nodes.size()) + " nodes)");
      const auto ci = static_cast<size_t>(c);
      if (ci == i) fail(node_label(m_, i), "cycle in the node hierarchy: the node is its own child");
      if (parent_[ci] >= 0)
        fail(node_label(m_, ci), "has two parents (" + node_label(m_, static_cast<size_t>(parent_[ci])) + " and " +
                                     node_label(m_, i) + "); glTF nodes form trees");
      parent_[ci] = static_cast<int>(i);
    }
  }
  // With one parent each, a cycle is a chain of parents that comes back to where it started.
  std::vector<int> state(m_.nodes.size(), 0);  // 0 unseen, 1 on the current chain, 2 known to end at a root
  for (size_t i = 0; i < m_.nodes.size(); ++i) {
    std::vector<size_t> chain;
    size_t n = i;
    while (state[n] == 0) {
      state[n] = 1;
      chain.push_back(n);
      if (parent_[n] < 0) break;
      n = static_cast<size_t>(parent_[n]);
    }
    if (state[n] == 1 && parent_[n] >= 0) {
      std::string cycle;
      const auto start = std::find(chain.begin(), chain.end(), n);
      for (auto it = start; it != chain.end(); ++it) cycle += node_label(m_, *it) + " -> ";
      fail(node_label(m_, n), "cycle in the node hierarchy (" + cycle + node_label(m_, n) + ", following parents)");
    }
    for (size_t c : chain) state[c] = 2;
  }
}

glm::dmat4 Loader::local_transform(size_t i) const {
  const tinygltf::Node& n = m_.nodes[i];
  const auto finite = [&](const std::vector<double>& v, const char* what) {
    for (double x : v)
      if (!std::isfinite(x)) fail(node_label(m_, i), std::string(what) + " has a value that is not finite");
  };
  if (!n.matrix.empty()) {
    if (n.matrix.size() != 16)
      fail(node_label(m_, i), "matrix has " + std::to_string(n.matrix.size()) + " values, expected 16");
    finite(n.matrix, "matrix");
    const glm::dmat4 m = glm::make_mat4(n.matrix.data());  // glTF matrices are column-major, as glm's
    return node_edit_[i] ? edited(*node_edit_[i], decompose(i, m)) : m;
  }
  Trs base;
  glm::dmat4 t(1.0), r(1.0), s(1.0);
  if (!n.translation.empty()) {
    if (n.translation.size() != 3)
      fail(node_label(m_, i), "translation has " + std::to_string(n.translation.size()) + " values, expected 3");
    finite(n.translation, "translation");
    base.translation = {n.translation[0], n.translation[1], n.translation[2]};
    t[3] = glm::dvec4(base.translation, 1.0);
  }
  if (!n.rotation.empty()) {
    if (n.rotation.size() != 4)
      fail(node_label(m_, i), "rotation has " + std::to_string(n.rotation.size()) + " values, expected 4 (x, y, z, w)");
    finite(n.rotation, "rotation");
    glm::dquat q(n.rotation[3], n.rotation[0], n.rotation[1], n.rotation[2]);
    // Exporters write unit quaternions rounded to float: normalise so rounding never scales; divided by its
    // largest component first, so that no length overflows (1e160 components made an infinite length and an
    // identity rotation) or underflows.
    const double big = std::max({std::abs(q.w), std::abs(q.x), std::abs(q.y), std::abs(q.z)});
    if (!(big > 0.0)) fail(node_label(m_, i), "rotation is a zero quaternion");
    q /= big;
    base.rotation = q / glm::length(q);
    r = glm::mat4_cast(base.rotation);
  }
  if (!n.scale.empty()) {
    if (n.scale.size() != 3)
      fail(node_label(m_, i), "scale has " + std::to_string(n.scale.size()) + " values, expected 3");
    finite(n.scale, "scale");
    base.scale = {n.scale[0], n.scale[1], n.scale[2]};
    s = glm::scale(glm::dmat4(1.0), base.scale);
  }
  return node_edit_[i] ? edited(*node_edit_[i], base) : t * r * s;
}

// Each node's world transform is computed once, from its parent's: a skin over a chain of 50,000 joints
// walked the chain from each joint (quadratic: 17 s for 20,000 joints, minutes for 50,000).
glm::dmat4 Loader::world_of(size_t node) const {
  if (world_known_.empty()) {
    world_.resize(m_.nodes.size());
    world_known_.assign(m_.nodes.size(), 0);
  }
  std::vector<size_t> chain;  // the node and its parents up to the first whose world transform is known
  size_t n = node;
  while (!world_known_[n]) {
    chain.push_back(n);
    if (parent_[n] < 0) break;
    n = static_cast<size_t>(parent_[n]);
  }
  glm::dmat4 w = world_known_[n] ? world_[n] : glm::dmat4(1.0);
  for (auto it = chain.rbegin(); it != chain.rend(); ++it) {
    w = w * local_transform(*it);
    world_[*it] = w;
    world_known_[*it] = 1;
  }
  return world_[node];
}

// The component types glTF 2.0 allows a vertex attribute (3.7.2.1), and those KHR_mesh_quantization adds when
// the file lists it in extensionsUsed: an UNSIGNED_INT POSITION was read as integer metres, a COLOR_0 of
// BYTE as negative colours, an UNSIGNED_INT NORMAL (no negative component) as some other direction, and a
// FLOAT JOINTS_0 as joint numbers.
void Loader::check_component(int accessor, const std::string& who, const std::string& attribute, bool morph) const {
  if (accessor < 0 || static_cast<size_t>(accessor) >= m_.accessors.size()) return;  // read_accessor names it
  enum Norm { kPlain, kNormalized, kEither };
  struct Allowed {
    int type;
    Norm norm;
  };
  constexpr int kF = TINYGLTF_COMPONENT_TYPE_FLOAT, kB = TINYGLTF_COMPONENT_TYPE_BYTE, kUB = TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE,
                kS = TINYGLTF_COMPONENT_TYPE_SHORT, kUS = TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT;
  std::vector<Allowed> core, quantized;
  const auto starts = [&](const char* prefix) { return attribute.rfind(prefix, 0) == 0; };
  if (attribute == "POSITION") {
    core = {{kF, kPlain}};
    quantized = morph ? std::vector<Allowed>{{kB, kEither}, {kS, kEither}}
                      : std::vector<Allowed>{{kB, kEither}, {kUB, kEither}, {kS, kEither}, {kUS, kEither}};
  } else if (attribute == "NORMAL") {
    core = {{kF, kPlain}};
    quantized = {{kB, kNormalized}, {kS, kNormalized}};
  } else if (starts("TEXCOORD_")) {
    core = {{kF, kPlain}, {kUB, kNormalized}, {kUS, kNormalized}};
    quantized = {{kB, kEither}, {kUB, kPlain}, {kS, kEither}, {kUS, kPlain}};
  } else if (attribute == "COLOR_0" || starts("WEIGHTS_")) {
    core = {{kF, kPlain}, {kUB, kNormalized}, {kUS, kNormalized}};
  } else if (starts("JOINTS_")) {
    core = {{kUB, kPlain}, {kUS, kPlain}};
  } else {
    return;  // not read
  }
  const bool declared = std::count(m_.extensionsUsed.begin(), m_.extensionsUsed.end(), "KHR_mesh_quantization") > 0;
  const tinygltf::Accessor& a = m_.accessors[static_cast<size_t>(accessor)];
  const auto fits = [&](const std::vector<Allowed>& list) {
    return std::any_of(list.begin(), list.end(), [&](const Allowed& x) {
      return x.type == a.componentType && (x.norm == kEither || (x.norm == kNormalized) == a.normalized || x.type == kF);
    });
  };
  if (fits(core) || (declared && fits(quantized))) return;
  const auto names = [](const std::vector<Allowed>& list) {
    std::string out;
    for (const Allowed& x : list)
      out += std::string(out.empty() ? "" : ", ") + component_name(x.type) +
             (x.type == kF || x.norm == kEither ? "" : x.norm == kNormalized ? " normalized" : " not normalized");
    return out;
  };
  std::string expected = names(core);
  if (declared) {
    if (!quantized.empty()) expected += ", " + names(quantized) + " (KHR_mesh_quantization)";
  } else if (fits(quantized)) {
    expected += "; " + component_name(a.componentType) + " needs KHR_mesh_quantization, which the file does not list in "
                "extensionsUsed (and extensionsRequired)";
  } else if (!quantized.empty()) {
    expected += " (with KHR_mesh_quantization in extensionsUsed also " + names(quantized) + ")";
  }
  fail(who, (morph ? "morph target " : "") + attribute + " accessor " + std::to_string(accessor) + " has componentType " +
                component_name(a.componentType) + (a.normalized ? " (normalized)" : "") + "; expected " + expected);
}

// glTF 2.0 skinning (linear blend) in the pose the nodes' own transforms give (no animation): a vertex's
// world position is sum_k weight_k x world(joint_k) x inverseBind(joint_k) x position; the transform of
// the node holding the mesh is not used (the specification's rule).
std::vector<glm::dmat4> Loader::skin_matrices(size_t node, const tinygltf::Primitive& p, size_t n, const std::string& who) {
  const auto skin_index = static_cast<size_t>(m_.nodes[node].skin);
  if (skin_index >= m_.skins.size())
    fail(node_label(m_, node), "skin " + std::to_string(m_.nodes[node].skin) + " does not exist (the file has " +
                                   std::to_string(m_.skins.size()) + " skins)");
  const tinygltf::Skin& skin = m_.skins[skin_index];
  const std::string skin_name = label("skin", skin_index, skin.name);
  if (skin.joints.empty()) fail(skin_name, "has no joints (glTF 2.0: joints has at least one node)");
  // skeleton, the joints' common root, is not used (the joints' world transforms are), but must be a node
  if (skin.skeleton >= 0 && static_cast<size_t>(skin.skeleton) >= m_.nodes.size())
    fail(skin_name, "skeleton " + std::to_string(skin.skeleton) + " is not a node (the file has " + std::to_string(m_.nodes.size()) +
                        " nodes)");
  std::vector<glm::dmat4> joint(skin.joints.size());
  std::vector<double> ibm;
  if (skin.inverseBindMatrices >= 0) {
    size_t count = 0;
    int c = 0;
    ibm = read_accessor(skin.inverseBindMatrices, skin_name + " inverseBindMatrices", {TINYGLTF_TYPE_MAT4}, &count, &c);
    if (count < skin.joints.size())
      fail(skin_name, "inverseBindMatrices holds " + std::to_string(count) + " matrices for " +
                          std::to_string(skin.joints.size()) + " joints");
  }
  for (size_t j = 0; j < skin.joints.size(); ++j) {
    const int jn = skin.joints[j];
    if (jn < 0 || static_cast<size_t>(jn) >= m_.nodes.size())
      fail(skin_name, "joint " + std::to_string(jn) + " is not a node (the file has " + std::to_string(m_.nodes.size()) + " nodes)");
    joint[j] = world_of(static_cast<size_t>(jn)) * (ibm.empty() ? glm::dmat4(1.0) : glm::make_mat4(ibm.data() + 16 * j));
  }
  std::vector<glm::dmat4> out(n, glm::dmat4(0.0));
  std::vector<double> sum(n, 0.0);  // of each vertex's weights
  bool any = false;
  for (int set = 0; set < 4; ++set) {
    const auto ji = p.attributes.find("JOINTS_" + std::to_string(set));
    const auto wi = p.attributes.find("WEIGHTS_" + std::to_string(set));
    if (ji == p.attributes.end() && wi == p.attributes.end()) break;
    if (ji == p.attributes.end() || wi == p.attributes.end())
      fail(who, "has " + std::string(ji == p.attributes.end() ? "WEIGHTS_" : "JOINTS_") + std::to_string(set) + " without " +
                    (ji == p.attributes.end() ? "JOINTS_" : "WEIGHTS_") + std::to_string(set));
    check_component(ji->second, who, "JOINTS_" + std::to_string(set), false);
    check_component(wi->second, who, "WEIGHTS_" + std::to_string(set), false);
    size_t kj = 0, kw = 0;
    int c = 0;
    const std::vector<double> js = read_accessor(ji->second, who + " JOINTS_" + std::to_string(set), {TINYGLTF_TYPE_VEC4}, &kj, &c);
    const std::vector<double> ws = read_accessor(wi->second, who + " WEIGHTS_" + std::to_string(set), {TINYGLTF_TYPE_VEC4}, &kw, &c);
    if (kj != n || kw != n)
      fail(who, "JOINTS_" + std::to_string(set) + " and WEIGHTS_" + std::to_string(set) + " have " + std::to_string(kj) + " and " +
                    std::to_string(kw) + " elements, POSITION " + std::to_string(n));
    any = true;
    for (size_t v = 0; v < n; ++v)
      for (int k = 0; k < 4; ++k) {
        const double w = ws[4 * v + static_cast<size_t>(k)];
        if (!(w >= 0.0)) fail(who, "WEIGHTS_" + std::to_string(set) + " element " + std::to_string(v) + " holds weight " + num(w) +
                                       " (glTF 2.0: weights are not negative)");
        if (w == 0.0) continue;
        const double j = js[4 * v + static_cast<size_t>(k)];
        if (!(j >= 0.0 && j < static_cast<double>(joint.size())))
          fail(who, "JOINTS_" + std::to_string(set) + " element " + std::to_string(v) + " names joint " + num(j) + " of " +
                        skin_name + "'s " + std::to_string(joint.size()));
        out[v] += w * joint[static_cast<size_t>(j)];
        sum[v] += w;
      }
  }
  if (!any) fail(who, "its node has " + skin_name + " but the primitive has no JOINTS_0 and WEIGHTS_0 (glTF 2.0: a skinned mesh has both)");
  // glTF 2.0: a vertex's weights sum to 1. None (a vertex bound to no joint) would put it at the origin; a
  // sum off by more than quantised weights can be (1 %) scales it towards the origin: normalised, and said.
  size_t off = 0, first_off = 0;
  for (size_t v = 0; v < n; ++v) {
    if (!(sum[v] > 0.0))
      fail(who, "the weights of vertex " + std::to_string(v) + " are all 0 (glTF 2.0: a vertex's weights sum to 1; it would stand "
                "at the origin)");
    if (std::abs(sum[v] - 1.0) > 1e-2) {
      if (off++ == 0) first_off = v;
      out[v] /= sum[v];
    }
  }
  if (off > 0)
    warn(who + ": the weights of " + std::to_string(off) + " of its " + std::to_string(n) + " vertices do not sum to 1 (vertex " +
         std::to_string(first_off) + ": " + num(sum[first_off]) + "); normalised, as glTF 2.0 asks them to be");
  return out;
}

// The scene file's edit of a node: each given component replaces the glTF's. The matrix is composed as an
// unedited node's is (T R S), so that an edit giving the glTF's own values changes no bit.
glm::dmat4 Loader::edited(const NodeEdit& e, const Trs& base) const {
  glm::dvec3 translation = base.translation, scale = base.scale;
  for (int k = 0; k < 3; ++k) {
    if (e.translation_m[k]) translation[k] = *e.translation_m[k];
    if (e.scale[k]) scale[k] = *e.scale[k];
  }
  glm::dmat4 t(1.0), r = glm::mat4_cast(base.rotation);
  t[3] = glm::dvec4(translation, 1.0);
  if (e.rotation_rad[0] || e.rotation_rad[1] || e.rotation_rad[2]) {
    // The angles not given are the glTF rotation's, in the same convention.
    glm::dvec3 angles = e.rotation_rad[0] && e.rotation_rad[1] && e.rotation_rad[2] ? glm::dvec3(0.0)
                                                                                     : euler_xyz_of(glm::mat3_cast(base.rotation));
    for (int k = 0; k < 3; ++k)
      if (e.rotation_rad[k]) angles[k] = *e.rotation_rad[k];
    r = glm::dmat4(euler_xyz(angles));
  }
  return t * r * glm::scale(glm::dmat4(1.0), scale);
}

// A 4 x 4 matrix whose last row is (0, 0, 0, 1) as translation, rotation and scale, and how far from its 3 x 3
// part they recompose, as a fraction of its largest entry (infinite for a zero scale): more than
// kDecomposeTolerance is a shear.
double decompose_trs(const glm::dmat4& m, Trs& out) {
  out.translation = glm::dvec3(m[3]);
  const glm::dmat3 a(m);
  for (int k = 0; k < 3; ++k) {
    out.scale[k] = glm::length(a[k]);
    if (!(out.scale[k] > 0.0)) return std::numeric_limits<double>::infinity();
  }
  if (glm::determinant(a) < 0.0) out.scale.x = -out.scale.x;  // a mirror: one negative scale
  out.rotation = glm::normalize(glm::quat_cast(glm::dmat3(a[0] / out.scale.x, a[1] / out.scale.y, a[2] / out.scale.z)));
  const glm::dmat3 back = glm::mat3_cast(out.rotation) * glm::dmat3(glm::scale(glm::dmat4(1.0), out.scale));
  double err = 0.0, size = 0.0;
  for (int c = 0; c < 3; ++c)
    for (int r = 0; r < 3; ++r) err = std::max(err, std::abs(back[c][r] - a[c][r])), size = std::max(size, std::abs(a[c][r]));
  return err / size;
}

bool affine(const glm::dmat4& m) { return m[0][3] == 0.0 && m[1][3] == 0.0 && m[2][3] == 0.0 && m[3][3] == 1.0; }

// A node's matrix as translation, rotation and scale, for an edit to replace some of them; an error naming
// the node when the matrix is not one (a shear, a last row other than (0, 0, 0, 1), a zero scale).
Trs Loader::decompose(size_t i, const glm::dmat4& m) const {
  const std::string who = node_label(m_, i);
  const std::string cannot = ", so the scene file's /nodes/" + pointer_token(m_.nodes[i].name) +
                             " cannot replace its translation, rotation or scale; give the node translation, rotation and "
                             "scale in the glTF file instead of a matrix";
  if (!affine(m)) fail(who, "its matrix's last row is not (0, 0, 0, 1)" + cannot);
  Trs out;
  const double residual = decompose_trs(m, out);
  if (std::isinf(residual)) fail(who, "its matrix has a zero scale" + cannot);
  if (!(residual <= kDecomposeTolerance))
    fail(who, "its matrix is not a translation, rotation and scale (it shears: recomposed from them it differs by " +
                  num(residual) + " of its largest entry, more than " + num(kDecomposeTolerance) + ")" + cannot);
  return out;
}

// glTF 2.0 (3.5.3): a node's matrix must decompose into translation, rotation and scale. A last row other
// than (0, 0, 0, 1) is a projection no renderer of positions applies: refused. A shear is rendered as given
// (normals by the inverse transpose), and said, since other readers may not (both were silent unless the
// scene file edited the node).
void Loader::check_matrix(size_t i) {
  const tinygltf::Node& n = m_.nodes[i];
  if (n.matrix.size() != 16) return;  // local_transform names it
  const glm::dmat4 m = glm::make_mat4(n.matrix.data());
  if (!affine(m))
    fail(node_label(m_, i), "its matrix's last row is (" + num(m[0][3]) + ", " + num(m[1][3]) + ", " + num(m[2][3]) + ", " +
                                num(m[3][3]) + "); expected (0, 0, 0, 1): glTF 2.0 node matrices are translation, rotation and "
                                "scale (3.5.3), and a projection cannot place vertices");
  Trs trs;
  const double residual = decompose_trs(m, trs);
  if (std::isfinite(residual) && residual > kDecomposeTolerance)  // (NaN: lengths past 1e154 overflowed; refused below)
    warn(node_label(m_, i) + ": its matrix shears (recomposed from a translation, rotation and scale it differs by " +
         num(residual) + " of its largest entry); glTF 2.0 requires matrices without shear (3.5.3), and other readers "
         "may place its meshes otherwise; rendered as given");
}

// "U+0063 U+0061 U+0066 U+00E9" of valid UTF-8 text (a byte that starts no sequence: U+FFFD).
std::string code_points(const std::string& v) {
  std::string out;
  for (size_t i = 0; i < v.size();) {
    const auto b = static_cast<unsigned char>(v[i]);
    const size_t n = b < 0x80 ? 1 : b >= 0xF0 ? 4 : b >= 0xE0 ? 3 : b >= 0xC0 ? 2 : 1;
    uint32_t cp = n == 1 ? (b < 0x80 ? b : 0xFFFD) : b & (0x7F >> n);
    for (size_t k = 1; k < n && i + k < v.size(); ++k) cp = cp << 6 | (static_cast<unsigned char>(v[i + k]) & 0x3F);
    char buf[12];
    std::snprintf(buf, sizeof buf, "U+%04X", static_cast<unsigned>(cp));
    if (!out.empty()) out += ' ';
    out += buf;
    i += n;
  }
  return out;
}

// The glTF element carrying `name` in `names` (kind "node", section "/nodes/"): exactly one must.
size_t Loader::named(const char* kind, const char* section, const std::vector<std::string>& names, const std::string& name) const {
  std::string key = section;  // built up: GCC 12 warns falsely (-Wrestrict) on const char* + std::string
  key += pointer_token(name);
  const std::string edits(section + 1, std::strlen(section) - 2);  // "/nodes/" -> "nodes
  const std::string shown = nlohmann::json(name).dump();
  std::vector<size_t> hits;
  for (size_t i = 0; i < names.size(); ++i)
    if (names[i] == name) hits.push_back(i);
  if (hits.size() == 1) return hits[0];
  if (hits.size() > 1) {
    std::string list;
    for (size_t h : hits) list += (list.empty() ? "" : ", ") + std::to_string(h);
    throw EditError(edits, name, one_line(key) + ": " + std::to_string(hits.size()) + " " + kind + "s of the glTF file " + path_ + " are named " + shown +
                " (" + kind + "s " + list + "); give them distinct names in the glTF file to edit one");
  }
  const auto lower = [](std::string v) {
    for (char& c : v) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    return v;
  };
  std::set<std::string> distinct;
  for (const std::string& n : names)
    if (!n.empty()) distinct.insert(n);
  std::string best;
  size_t best_d = std::max<size_t>(2, name.size() / 3) + 1;
  for (const std::string& n : distinct)
    if (const size_t d = edit_distance(lower(name), lower(n)); d < best_d) best_d = d, best = n;
  std::string msg = key + ": the glTF file " + path_ + " has no " + kind + " named " + shown;
  if (!best.empty()) {
    msg += "; did you mean " + nlohmann::json(best).dump();
    // Two spellings of one accented name (NFC and NFD: "caf\u00e9" and "cafe\u0301") print alike: their code
    // points tell them apart.
    const auto non_ascii = [](const std::string& v) {
      return std::any_of(v.begin(), v.end(), [](char c) { return static_cast<unsigned char>(c) >= 0x80; });
    };
    if (non_ascii(best) && non_ascii(name))
      msg += " (code points " + code_points(best) + "; you gave " + code_points(name) + ")";
    msg += "?";
  }
  if (distinct.empty()) {
    msg += std::string(" (none of its ") + kind + "s has a name)";
  } else if (distinct.size() <= 12) {
    msg += std::string(" (its ") + kind + "s:";
    for (const std::string& n : distinct) {
      msg += n == *distinct.begin() ? " " : ", ";
      msg += nlohmann::json(n).dump();
    }
    msg += ')';
  } else {
    msg += " (it has " + std::to_string(distinct.size()) + " named " + kind + "s; spadgen info lists them)";
  }
  throw EditError(edits, name, one_line(msg));
}

void Loader::resolve_edits() {
  node_edit_.assign(m_.nodes.size(), nullptr);
  material_edit_.assign(m_.materials.size(), nullptr);
  std::vector<std::string> names;
  for (const tinygltf::Node& n : m_.nodes) names.push_back(n.name);
  for (const NodeEdit& e : edits_.nodes) node_edit_[named("node", "/nodes/", names, e.name)] = &e;
  names.clear();
  for (const tinygltf::Material& m : m_.materials) names.push_back(m.name);
  for (const MaterialEdit& e : edits_.materials) material_edit_[named("material", "/materials/", names, e.name)] = &e;
}

// Edits that change nothing: of a material no loaded mesh uses, of a node outside the loaded glTF scene.
void Loader::warn_unused_edits() {
  for (size_t i = 0; i < material_edit_.size(); ++i) {
    if (!material_edit_[i]) continue;
    const bool used = std::any_of(scene_.meshes.begin(), scene_.meshes.end(),
                                  [&](const Mesh& mesh) { return mesh.material == static_cast<int>(i); });
    if (!used)
      warn("/materials/" + pointer_token(m_.materials[i].name) + ": " + label("material", i, m_.materials[i].name) +
           " is used by no mesh of the loaded scene; the edit changes nothing");
  }
  // A node outside the scene still places a loaded skinned mesh when it is one of its skin's joints, or
  // above one: its joints' world transforms are composed whatever scene they are in (it was warned as
  // changing nothing, and moved the mesh).
  std::vector<char> poses(m_.nodes.size(), 0);
  for (size_t i = 0; i < m_.nodes.size(); ++i) {
    const int skin = m_.nodes[i].skin;
    if (!scene_.nodes[i].loaded || m_.nodes[i].mesh < 0 || skin < 0 || static_cast<size_t>(skin) >= m_.skins.size()) continue;
    for (const int j : m_.skins[static_cast<size_t>(skin)].joints)
      for (int n = j; n >= 0 && static_cast<size_t>(n) < m_.nodes.size() && !poses[static_cast<size_t>(n)];
           n = parent_[static_cast<size_t>(n)])
        poses[static_cast<size_t>(n)] = 1;
  }
  for (size_t i = 0; i < node_edit_.size(); ++i) {
    if (node_edit_[i] && !scene_.nodes[i].loaded && !poses[i])
      warn("/nodes/" + pointer_token(m_.nodes[i].name) + ": " + node_label(m_, i) +
           " is not part of the loaded glTF scene; the edit changes nothing");
    // glTF 2.0 places a skinned mesh by its skin's joints, not by the node that holds it
    else if (node_edit_[i] && m_.nodes[i].skin >= 0 && m_.nodes[i].children.empty() && m_.nodes[i].camera < 0 &&
             !m_.nodes[i].extensions.count("KHR_lights_punctual") &&
             std::none_of(m_.skins.begin(), m_.skins.end(), [i](const tinygltf::Skin& sk) {
               return std::find(sk.joints.begin(), sk.joints.end(), static_cast<int>(i)) != sk.joints.end();
             }))
      warn("/nodes/" + pointer_token(m_.nodes[i].name) + ": " + node_label(m_, i) +
           " holds a skinned mesh, which its skin's joints place (glTF 2.0 ignores the transform of its node); the edit "
           "changes nothing: edit the joints' nodes");
  }
}

// Depth first, children in order (the order of Scene::meshes), with an explicit stack: a parent chain
// as deep as the file is long must not exhaust the call stack.
void Loader::visit(int root, const glm::dmat4& root_world) {
  std::vector<std::pair<int, glm::dmat4>> stack{{root, root_world}};
  while (!stack.empty()) {
    const auto [node, parent_world] = stack.back();
    stack.pop_back();
    visit_one(node, parent_world, stack);
  }
}

void Loader::visit_one(int node, const glm::dmat4& parent_world, std::vector<std::pair<int, glm::dmat4>>& stack) {
  const auto i = static_cast<size_t>(node);
  const glm::dmat4 world = parent_world * local_transform(i);
  check_matrix(i);
  scene_.nodes[i].loaded = true;
  scene_.nodes[i].world = world;
  const tinygltf::Node& n = m_.nodes[i];
  if (n.mesh >= 0) {
    if (static_cast<size_t>(n.mesh) >= m_.meshes.size())
      fail(node_label(m_, i), "mesh " + std::to_string(n.mesh) + " does not exist (the file has " +
                                  std::to_string(m_.meshes.size()) + " meshes)");
    const double det = glm::determinant(glm::dmat3(world));
    // A scale past 1e100 overflows the determinant: every vertex but the origin lies beyond what is traced (it
    // was called a zero scale).
    if (n.skin < 0 && !std::isfinite(det))
      fail(node_label(m_, i), "its world transform scales volumes by " + num(det) + " (its own and its parents' scales "
                              "multiplied): its mesh's vertices would lie beyond +-" + num(kMaxWorldCoordinate) +
                              " m, which spadgen traces; expected scales that keep the scene within that");
    if (n.skin < 0 && !(std::abs(det) > 1e-300)) {  // (a skinned mesh: its skin's)
      warn(node_label(m_, i) + ": its world transform is singular (a zero scale, determinant " + num(det) + "); its mesh is skipped");
    } else {
      const tinygltf::Mesh& mesh = m_.meshes[static_cast<size_t>(n.mesh)];
      if (mesh.primitives.empty())
        fail("mesh " + std::to_string(n.mesh) + (mesh.name.empty() ? "" : " '" + scenes::printable(mesh.name) + "'"),
             "has no primitives; glTF 2.0 requires at least one (meshes[].primitives, minItems 1)");
      for (size_t p = 0; p < mesh.primitives.size(); ++p) load_primitive(i, static_cast<size_t>(n.mesh), p, world);
    }
  }
  if (n.camera >= 0) load_camera(i, world);
  if (n.extensions.count("KHR_lights_punctual")) load_light(i, world);
  for (auto c = n.children.rbegin(); c != n.children.rend(); ++c) stack.emplace_back(*c, world);
}

void Loader::check_view_range(int view_index, size_t offset, size_t bytes, const std::string& who) {
  if (view_index < 0 || static_cast<size_t>(view_index) >= m_.bufferViews.size())
    fail(who, "bufferView " + std::to_string(view_index) + " does not exist (the file has " +
                  std::to_string(m_.bufferViews.size()) + " bufferViews)");
  const tinygltf::BufferView& view = m_.bufferViews[static_cast<size_t>(view_index)];
  const std::string view_name = label("bufferView", static_cast<size_t>(view_index), view.name);
  if (view.buffer < 0 || static_cast<size_t>(view.buffer) >= m_.buffers.size())
    fail(view_name, "buffer " + std::to_string(view.buffer) + " does not exist (the file has " +
                        std::to_string(m_.buffers.size()) + " buffers)");
  const tinygltf::Buffer& buffer = m_.buffers[static_cast<size_t>(view.buffer)];
  const size_t size = buffer.data.size();
  if (view.byteOffset > size || view.byteLength > size - view.byteOffset)
    fail(view_name, "bytes " + std::to_string(view.byteOffset) + " to " +
                        std::to_string(view.byteOffset + view.byteLength) + " lie past the end of " +
                        buffer_label(static_cast<size_t>(view.buffer), buffer) +
                        " (" + std::to_string(size) + " bytes)");
  if (offset > view.byteLength || bytes > view.byteLength - offset)
    fail(who, "reads bytes " + std::to_string(offset) + " to " + std::to_string(offset + bytes) +
                  " of its bufferView " + std::to_string(view_index) + ", past its end (" +
                  std::to_string(view.byteLength) + " bytes)");
}

std::vector<double> Loader::read_accessor(int index, const std::string& user, std::initializer_list<int> types,
                                          size_t* count_out, int* components_out) {
  if (index < 0 || static_cast<size_t>(index) >= m_.accessors.size())
    fail(user, "accessor " + std::to_string(index) + " does not exist (the file has " +
                   std::to_string(m_.accessors.size()) + " accessors)");
  const tinygltf::Accessor& a = m_.accessors[static_cast<size_t>(index)];
  const std::string who = label("accessor", static_cast<size_t>(index), a.name) + " (" + user + ")";
  if (std::find(types.begin(), types.end(), a.type) == types.end()) {
    std::string expected;
    for (int t : types) expected += std::string(expected.empty() ? "" : " or ") + type_name(t);
    fail(who, std::string("type ") + type_name(a.type) + ", expected " + expected);
  }
  const size_t csize = component_size(a.componentType);
  if (csize == 0) fail(who, "componentType " + std::to_string(a.componentType) + " is not a glTF 2.0 component type");
  // glTF 3.6.2.1: normalized MUST NOT be true for FLOAT or UNSIGNED_INT (a FLOAT's was ignored; an UNSIGNED_INT
  // index accessor's values were divided by 2^32 - 1, every triangle collapsed to vertex 0).
  if (a.normalized && (a.componentType == TINYGLTF_COMPONENT_TYPE_FLOAT || a.componentType == TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT))
    fail(who, std::string("normalized is true for a ") + component_name(a.componentType) +
                  " accessor; expected it only for BYTE, UNSIGNED_BYTE, SHORT and UNSIGNED_SHORT (glTF 2.0, 3.6.2.1)");
  const int comps = type_components(a.type);
  const size_t elem = csize * static_cast<size_t>(comps);
  const size_t count = a.count;
  // With a bufferView the count is bounded by the bytes behind it (checked before allocating); an
  // accessor without one is zeros (plus sparse values), which no real file makes this large.
  if (a.bufferView < 0 && count > (size_t{1} << 24))
    fail(who, "count " + std::to_string(count) + " without a bufferView is implausibly large");
  if (count > (size_t{1} << 40)) fail(who, "count " + std::to_string(count) + " is implausibly large");

  size_t stride = elem;
  if (a.bufferView >= 0) {
    check_view_range(a.bufferView, 0, 0, who);
    const tinygltf::BufferView& view = m_.bufferViews[static_cast<size_t>(a.bufferView)];
    if (view.byteStride != 0 && view.byteStride < elem)
      fail(label("bufferView", static_cast<size_t>(a.bufferView), view.name),
           "byteStride " + std::to_string(view.byteStride) + " is smaller than the " + std::to_string(elem) +
               "-byte elements of " + who);
    if (view.byteStride != 0) stride = view.byteStride;
    if (count > 1 && count - 1 > (std::numeric_limits<size_t>::max() - elem) / stride)
      fail(who, "count " + std::to_string(count) + " times byteStride " + std::to_string(stride) + " overflows");
    if (count > 0) check_view_range(a.bufferView, a.byteOffset, (count - 1) * stride + elem, who);
    // glTF 2.0 3.6.2.4: offsets (and a vertex attribute's byteStride) MUST be multiples of the component size.
    // Read as written (unaligned reads are exact), and said: an exporter that misaligns them may have put
    // the data elsewhere (a float accessor at byteOffset 2 loaded without a word; an auditor's find).
    if (a.byteOffset % csize != 0 || (view.byteOffset + a.byteOffset) % csize != 0 || stride % csize != 0)
      warn(who + ": its byteOffset " + std::to_string(a.byteOffset) + ", its bufferView's byteOffset " + std::to_string(view.byteOffset) +
           " and byteStride " + std::to_string(view.byteStride) + " are not all multiples of its " + std::to_string(csize) +
           "-byte components, which glTF 2.0 requires (3.6.2.4); read as written: check the exporter");
  }
  std::vector<double> out(count * static_cast<size_t>(comps), 0.0);
  if (a.bufferView >= 0) {
    const tinygltf::BufferView& view = m_.bufferViews[static_cast<size_t>(a.bufferView)];
    const unsigned char* base =
        m_.buffers[static_cast<size_t>(view.buffer)].data.data() + view.byteOffset + a.byteOffset;
    for (size_t e = 0; e < count; ++e)
      for (int c = 0; c < comps; ++c)
        out[e * static_cast<size_t>(comps) + static_cast<size_t>(c)] =
            read_component(base + e * stride + static_cast<size_t>(c) * csize, a.componentType, a.normalized);
  }
  // Without a bufferView the accessor is zeros, possibly with sparse values on top (glTF 3.6.2.3).
  if (a.sparse.isSparse) {
    const int n = a.sparse.count;
    if (n < 1 || static_cast<size_t>(n) > count)
      fail(who, "sparse.count " + std::to_string(n) + " is outside [1, " + std::to_string(count) + "]");
    const int itype = a.sparse.indices.componentType;
    const size_t isize = component_size(itype);
    if (itype != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && itype != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
        itype != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
      fail(who, "sparse.indices.componentType " + std::to_string(itype) + " is not an unsigned integer type");
    if (a.sparse.indices.byteOffset < 0 || a.sparse.values.byteOffset < 0) fail(who, "sparse byteOffset is negative");
    const auto un = static_cast<size_t>(n);
    check_view_range(a.sparse.indices.bufferView, static_cast<size_t>(a.sparse.indices.byteOffset), un * isize,
                     who + " sparse.indices");
    check_view_range(a.sparse.values.bufferView, static_cast<size_t>(a.sparse.values.byteOffset), un * elem,
                     who + " sparse.values");
    const auto bytes_of = [&](int view_index, int offset) {
      const tinygltf::BufferView& v = m_.bufferViews[static_cast<size_t>(view_index)];
      return m_.buffers[static_cast<size_t>(v.buffer)].data.data() + v.byteOffset + static_cast<size_t>(offset);
    };
    const unsigned char* idx = bytes_of(a.sparse.indices.bufferView, a.sparse.indices.byteOffset);
    const unsigned char* val = bytes_of(a.sparse.values.bufferView, a.sparse.values.byteOffset);
    for (size_t k = 0, previous = 0; k < un; ++k) {
      const auto target = static_cast<size_t>(read_component(idx + k * isize, itype, false));
      if (target >= count)
        fail(who, "sparse index " + std::to_string(target) + " is out of range of its " + std::to_string(count) +
                      " elements");
      // glTF 3.6.2.3: the indices MUST strictly increase (a repeated index was read as the last value).
      if (k > 0 && target <= previous)
        fail(who, "sparse.indices[" + std::to_string(k) + "] is " + std::to_string(target) + " after " +
                      std::to_string(previous) + "; expected strictly increasing indices (glTF 2.0, 3.6.2.3)");
      previous = target;
      for (int c = 0; c < comps; ++c)
        out[target * static_cast<size_t>(comps) + static_cast<size_t>(c)] =
            read_component(val + k * elem + static_cast<size_t>(c) * csize, a.componentType, a.normalized);
    }
  }
  for (double v : out)
    if (!std::isfinite(v)) fail(who, "holds a value that is not finite");
  *count_out = count;
  *components_out = comps;
  return out;
}

double Loader::number(const tinygltf::Value& object, const char* key, double fallback, const std::string& who) const {
  if (!object.IsObject() || !object.Has(key)) return fallback;
  const tinygltf::Value& v = object.Get(key);
  if (!v.IsNumber()) fail(who, std::string(key) + " is not a number");
  const double d = v.GetNumberAsDouble();
  if (!std::isfinite(d)) fail(who, std::string(key) + " is not finite");
  return d;
}

glm::dvec3 Loader::vec3(const std::vector<double>& v, glm::dvec3 fallback, const std::string& who, const char* what) const {
  if (v.empty()) return fallback;
  if (v.size() != 3) fail(who, std::string(what) + " has " + std::to_string(v.size()) + " values, expected 3");
  for (double x : v)
    if (!std::isfinite(x)) fail(who, std::string(what) + " has a value that is not finite");
  return {v[0], v[1], v[2]};
}

void Loader::check_world(const glm::dvec3& p, const std::string& who, const std::string& what) const {
  for (int k = 0; k < 3; ++k)
    if (!(std::abs(p[k]) <= kMaxWorldCoordinate))
      fail(who, what + " lies at (" + num(p.x) + ", " + num(p.y) + ", " + num(p.z) + ") m in the world, beyond +-" +
                    num(kMaxWorldCoordinate) + " m, which spadgen traces");
}

int Loader::texture(int gltf_texture, const std::string& user) {
  if (auto it = texture_of_gltf_.find(gltf_texture); it != texture_of_gltf_.end()) return it->second;
  if (gltf_texture < 0 || static_cast<size_t>(gltf_texture) >= m_.textures.size())
    fail(user, "texture " + std::to_string(gltf_texture) + " does not exist (the file has " +
                   std::to_string(m_.textures.size()) + " textures)");
  const tinygltf::Texture& t = m_.textures[static_cast<size_t>(gltf_texture)];
  const std::string tname = label("texture", static_cast<size_t>(gltf_texture), t.name);
  int result = -1;
  if (t.source < 0) {
    // KHR_texture_basisu and EXT_texture_webp put their image in an extension: unsupported here.
    warn(tname + ": has no image spadgen can read; " + user + " uses its factor only");
  } else if (static_cast<size_t>(t.source) >= m_.images.size()) {
    fail(tname, "image " + std::to_string(t.source) + " does not exist (the file has " +
                    std::to_string(m_.images.size()) + " images)");
  } else {
    tinygltf::Image& img = images_[static_cast<size_t>(t.source)];
    std::shared_ptr<const std::vector<uint8_t>>& texels = texels_of_image_[t.source];
    const std::string iname = label("image", static_cast<size_t>(t.source), img.name.empty() ? img.uri : img.name);
    if (img.as_is)  // (load_image_checked)
      fail(tname, "its source, " + iname + ", is " + (img.mimeType == "image/ktx2" ? "KTX2 (KHR_texture_basisu)" : "WebP (EXT_texture_webp)") +
                      ", which spadgen does not decode; a texture's source is PNG or JPEG (glTF 2.0: the extension's "
                      "fallback), used by " + user);
    // Every decoded image is RGBA8 (load_image_checked, image_decode.h, which also bounds its size); an
    // image file that could not be read leaves none.
    const size_t w = img.width > 0 ? static_cast<size_t>(img.width) : 0;
    const size_t h = img.height > 0 ? static_cast<size_t>(img.height) : 0;
    if (texels == nullptr && (img.image.empty() || img.component != 4 || img.bits != 8 || img.image.size() != w * h * 4)) {
      const auto file = image_files_.find(t.source);
      warn(iname + (file != image_files_.end() ? ": " + file->second : std::string(": could not be read or decoded")) + "; " + user +
           " uses its factor only");
    } else {
      Texture tex;
      tex.name = t.name.empty() ? img.name : t.name;
      tex.width = img.width;
      tex.height = img.height;
      // the decoded image moved (not copied) into the scene, once for the textures that use it
      if (texels == nullptr) texels = std::make_shared<const std::vector<uint8_t>>(std::move(img.image));
      tex.texels = texels;
      if (t.sampler >= 0) {
        if (static_cast<size_t>(t.sampler) >= m_.samplers.size())
          fail(tname, "sampler " + std::to_string(t.sampler) + " does not exist (the file has " +
                          std::to_string(m_.samplers.size()) + " samplers)");
        const tinygltf::Sampler& s = m_.samplers[static_cast<size_t>(t.sampler)];
        for (int wrap : {s.wrapS, s.wrapT})
          if (wrap != TINYGLTF_TEXTURE_WRAP_REPEAT && wrap != TINYGLTF_TEXTURE_WRAP_CLAMP_TO_EDGE &&
              wrap != TINYGLTF_TEXTURE_WRAP_MIRRORED_REPEAT)
            fail(label("sampler", static_cast<size_t>(t.sampler), s.name), "wrap mode " + std::to_string(wrap) + " is not a glTF wrap mode");
        tex.wrap_s = s.wrapS;
        tex.wrap_t = s.wrapT;
        // NEAREST (9728) and its mipmap variants (9984 NEAREST_MIPMAP_NEAREST, 9986 NEAREST_MIPMAP_LINEAR).
        for (int filter : {s.magFilter, s.minFilter})
          if (filter == 9728 || filter == 9984 || filter == 9986)
            warn(label("sampler", static_cast<size_t>(t.sampler), s.name) +
                 ": NEAREST filtering is not used; its textures are filtered bilinearly");
      }
      scene_.textures.push_back(std::move(tex));
      result = static_cast<int>(scene_.textures.size()) - 1;
    }
  }
  texture_of_gltf_[gltf_texture] = result;
  return result;
}

void Loader::load_materials() {
  for (size_t i = 0; i < m_.materials.size(); ++i) {
    const tinygltf::Material& g = m_.materials[i];
    const std::string who = label("material", i, g.name);
    Material mat;
    mat.name = g.name;
    const tinygltf::PbrMetallicRoughness& pbr = g.pbrMetallicRoughness;
    if (pbr.baseColorFactor.size() != 4)
      fail(who, "baseColorFactor has " + std::to_string(pbr.baseColorFactor.size()) + " values, expected 4");
    for (double c : pbr.baseColorFactor)
      if (!(c >= 0.0 && c <= 1.0)) fail(who, "baseColorFactor value " + num(c) + " is outside [0, 1]");
    mat.base_color = glm::vec4(glm::dvec4(pbr.baseColorFactor[0], pbr.baseColorFactor[1], pbr.baseColorFactor[2],
                                          pbr.baseColorFactor[3]));
    if (!(pbr.metallicFactor >= 0 && pbr.metallicFactor <= 1))
      fail(who, "metallicFactor " + num(pbr.metallicFactor) + " is outside [0, 1]");
    if (!(pbr.roughnessFactor >= 0 && pbr.roughnessFactor <= 1))
      fail(who, "roughnessFactor " + num(pbr.roughnessFactor) + " is outside [0, 1]");
    mat.metallic = static_cast<float>(pbr.metallicFactor);
    mat.roughness = static_cast<float>(pbr.roughnessFactor);
    if (pbr.baseColorTexture.index >= 0) {
      int set = pbr.baseColorTexture.texCoord;
      // KHR_texture_transform (gltfpack writes it with quantized texture coordinates, which it maps onto the
      // texture): offset, rotation (radians, counter-clockwise in UV space) and scale, T R S, and texCoord, which
      // replaces the texture's.
      if (const auto tt = pbr.baseColorTexture.extensions.find("KHR_texture_transform"); tt != pbr.baseColorTexture.extensions.end()) {
        const tinygltf::Value& t = tt->second;
        const std::string at = who + " baseColorTexture KHR_texture_transform";
        if (!t.IsObject()) fail(at, "expected an object");
        const auto pair = [&](const char* key, double fallback) -> std::array<double, 2> {
          if (!t.Has(key)) return {fallback, fallback};
          const tinygltf::Value& v = t.Get(key);
          if (!v.IsArray() || v.ArrayLen() != 2 || !v.Get(0).IsNumber() || !v.Get(1).IsNumber())
            fail(at, std::string(key) + ": expected an array of 2 numbers");
          const std::array<double, 2> out = {v.Get(0).GetNumberAsDouble(), v.Get(1).GetNumberAsDouble()};
          if (!std::isfinite(out[0]) || !std::isfinite(out[1])) fail(at, std::string(key) + " is not finite");
          return out;
        };
        const std::array<double, 2> offset = pair("offset", 0.0), scale = pair("scale", 1.0);
        const double r = number(t, "rotation", 0.0, at), c = std::cos(r), sn = std::sin(r);
        uv_transform_[static_cast<int>(i)] = {c * scale[0], sn * scale[1], offset[0], -sn * scale[0], c * scale[1], offset[1]};
        if (t.Has("texCoord")) {
          if (!t.Get("texCoord").IsInt() || t.Get("texCoord").GetNumberAsInt() < 0) fail(at, "texCoord: expected an integer >= 0");
          set = t.Get("texCoord").GetNumberAsInt();
        }
      }
      if (set < 0 || set > 1) {
        warn(who + ": baseColorTexture uses TEXCOORD_" + std::to_string(set) +
             "; spadgen reads TEXCOORD_0 and TEXCOORD_1 only, so the texture is not used");
      } else {
        mat.base_color_texture = texture(pbr.baseColorTexture.index, who + " baseColorTexture");
        mat.base_color_texcoord = set;
        mat.base_color_transformed = uv_transform_.count(static_cast<int>(i)) > 0;
      }
    }
    const auto unused_texture = [&](int index, const char* what) {
      if (index >= 0)
        warn(who + ": " + what + " is not used by spadgen; ignored");
    };
    unused_texture(pbr.metallicRoughnessTexture.index, "metallicRoughnessTexture (the factors are used)");
    unused_texture(g.normalTexture.index, "normalTexture");
    unused_texture(g.occlusionTexture.index, "occlusionTexture");
    unused_texture(g.emissiveTexture.index, "emissiveTexture (emissiveFactor is used)");
    if (g.alphaMode != "OPAQUE" && g.alphaMode != "MASK" && g.alphaMode != "BLEND")
      fail(who, "alphaMode " + quoted(g.alphaMode) + " is no glTF 2.0 alpha mode; expected OPAQUE, MASK or BLEND");
    if (g.alphaMode != "OPAQUE")
      warn(who + ": alphaMode " + g.alphaMode + " is not used by spadgen; the surface is opaque");
    mat.double_sided = g.doubleSided;

    glm::dvec3 emissive = vec3(g.emissiveFactor, {0, 0, 0}, who, "emissiveFactor");
    for (int k = 0; k < 3; ++k)
      if (!(emissive[k] >= 0.0 && emissive[k] <= 1.0)) fail(who, "emissiveFactor value " + num(emissive[k]) + " is outside [0, 1]");
    const auto ext = [&](const char* name) -> const tinygltf::Value* {
      auto it = g.extensions.find(name);
      if (it == g.extensions.end()) return nullptr;
      if (!it->second.IsObject()) fail(who, std::string(name) + " is not a JSON object");
      return &it->second;
    };
    const auto ext_texture = [&](const tinygltf::Value* e, const char* ext_name, const char* key) {
      if (e && e->Has(key)) warn(who + ": " + ext_name + "." + key + " is not used by spadgen; the factor is used");
    };
    if (const tinygltf::Value* e = ext("KHR_materials_emissive_strength")) {
      const double s = number(*e, "emissiveStrength", 1.0, who + " KHR_materials_emissive_strength");
      if (s < 0) fail(who, "KHR_materials_emissive_strength.emissiveStrength " + num(s) + " is negative");
      emissive *= s;
    }
    if (const double peak = std::max({emissive.x, emissive.y, emissive.z}); peak > kMaxEmissiveNits)
      fail(who, "emits " + num(peak) + " nits (emissiveFactor times KHR_materials_emissive_strength.emissiveStrength), "
                "expected at most " + num(kMaxEmissiveNits) + " (600 times the sun's disc)");
    mat.emissive = glm::vec3(emissive);
    if (const tinygltf::Value* e = ext("KHR_materials_transmission")) {
      const double t = number(*e, "transmissionFactor", 0.0, who + " KHR_materials_transmission");
      if (t < 0 || t > 1) fail(who, "KHR_materials_transmission.transmissionFactor " + num(t) + " is outside [0, 1]");
      mat.transmission = static_cast<float>(t);
      ext_texture(e, "KHR_materials_transmission", "transmissionTexture");
    }
    if (const tinygltf::Value* e = ext("KHR_materials_ior")) {
      const double n = number(*e, "ior", 1.5, who + " KHR_materials_ior");
      if (n < 1.0) fail(who, "KHR_materials_ior.ior " + num(n) + " is below 1");
      // the renderer's Fresnel squares it in single precision: past 1.8e19 that was infinite, and NaN followed
      if (n > 1e6) fail(who, "KHR_materials_ior.ior " + num(n) + " is above 1e6; expected an index of refraction in [1, 1e6]");
      mat.ior = static_cast<float>(n);
    }
    if (const tinygltf::Value* e = ext("KHR_materials_volume")) {
      const std::string vw = who + " KHR_materials_volume";
      const double thickness = number(*e, "thicknessFactor", 0.0, vw);
      if (thickness < 0) fail(who, "KHR_materials_volume.thicknessFactor " + num(thickness) + " is negative");
      mat.thickness_m = static_cast<float>(thickness);
      const double dist = number(*e, "attenuationDistance", std::numeric_limits<double>::infinity(), vw);
      if (!(dist > 0)) fail(who, "KHR_materials_volume.attenuationDistance " + num(dist) + " must be > 0");
      // Below a nanometre a medium absorbs everything at its surface; below 1.2e-38 m the distance was 0 or a
      // denormal in single precision, and the medium was taken as clear.
      if (dist < 1e-9)
        fail(who, "KHR_materials_volume.attenuationDistance " + num(dist) + " m is below 1e-9 m: such a medium absorbs "
                  "all light within a nanometre of its surface; expected a distance of at least 1e-9 m (for an opaque "
                  "material, no KHR_materials_transmission)");
      mat.attenuation_distance_m = static_cast<float>(dist);
      if (e->Has("attenuationColor")) {
        const tinygltf::Value& c = e->Get("attenuationColor");
        if (!c.IsArray() || c.ArrayLen() != 3) fail(who, "KHR_materials_volume.attenuationColor is not an array of 3 numbers");
        for (int k = 0; k < 3; ++k) {
          if (!c.Get(k).IsNumber()) fail(who, "KHR_materials_volume.attenuationColor is not an array of 3 numbers");
          const double v = c.Get(k).GetNumberAsDouble();
          if (!(v >= 0 && v <= 1)) fail(who, "KHR_materials_volume.attenuationColor value " + num(v) + " is outside [0, 1]");
          mat.attenuation_color[k] = static_cast<float>(v);
        }
      }
      ext_texture(e, "KHR_materials_volume", "thicknessTexture");
    }
    if (const MaterialEdit* e = material_edit_[i]) mat.apply(*e);
    scene_.materials.push_back(std::move(mat));
  }
}

void Loader::load_primitive(size_t node, size_t mesh_index, size_t prim_index, const glm::dmat4& world) {
  const tinygltf::Mesh& gm = m_.meshes[mesh_index];
  const tinygltf::Primitive& p = gm.primitives[prim_index];
  const std::string who = label("mesh", mesh_index, gm.name) + " primitive " + std::to_string(prim_index);
  if (p.mode != TINYGLTF_MODE_TRIANGLES && p.mode != TINYGLTF_MODE_TRIANGLE_STRIP &&
      p.mode != TINYGLTF_MODE_TRIANGLE_FAN) {
    if (p.mode >= 0 && p.mode <= 3)
      warn(who + ": mode " + mode_name(p.mode) + " is not used by spadgen; skipped");
    else
      fail(who, "mode " + std::to_string(p.mode) + " is not a glTF primitive mode");
    return;
  }
  if (p.material >= 0 && static_cast<size_t>(p.material) >= m_.materials.size())
    fail(who, "material " + std::to_string(p.material) + " does not exist (the file has " +
                  std::to_string(m_.materials.size()) + " materials)");
  const auto pos_it = p.attributes.find("POSITION");
  if (pos_it == p.attributes.end()) fail(who, "has no POSITION attribute");

  Mesh out;
  const tinygltf::Node& gn = m_.nodes[node];
  out.name = (gn.name.empty() ? "node" + std::to_string(node) : gn.name) + "/" +
             (gm.name.empty() ? "mesh" + std::to_string(mesh_index) : gm.name) + "/" + std::to_string(prim_index);
  out.gltf_node = static_cast<int>(node);
  out.gltf_mesh = static_cast<int>(mesh_index);
  out.gltf_primitive = static_cast<int>(prim_index);
  out.material = p.material;

  size_t n = 0, k = 0;
  int comps = 0;
  check_component(pos_it->second, who, "POSITION", false);
  std::vector<double> pos = read_accessor(pos_it->second, who + " POSITION", {TINYGLTF_TYPE_VEC3}, &n, &comps);
  // Morph targets: the shape of the default weights (the node's, else the mesh's; none: the base shape),
  // base + sum of weight x target displacement, for POSITION and NORMAL.
  const std::vector<double>& weights = !gn.weights.empty() ? gn.weights : gm.weights;
  if (!weights.empty() && weights.size() != p.targets.size())
    fail(who, "has " + std::to_string(p.targets.size()) + " morph targets but " +
                  (gn.weights.empty() ? label("mesh", mesh_index, gm.name) : node_label(m_, node)) + " gives " +
                  std::to_string(weights.size()) + " weights (glTF 2.0: one per target)");
  // Every target's accessors exist and hold one element per vertex, whatever the weights (glTF 2.0: a target's
  // accessors have the base's count; a target of weight 0 named accessor 77 of 3, or held 2 of 3 vertices, silently).
  for (size_t t = 0; t < p.targets.size(); ++t)
    for (const auto& [attribute, accessor] : p.targets[t])
      if (accessor < 0 || static_cast<size_t>(accessor) >= m_.accessors.size())
        fail(who, "morph target " + std::to_string(t) + " " + attribute + ": accessor " + std::to_string(accessor) +
                      " does not exist (the file has " + std::to_string(m_.accessors.size()) + " accessors)");
      else if (m_.accessors[static_cast<size_t>(accessor)].count != n)
        fail(who, "morph target " + std::to_string(t) + " " + attribute + " has " +
                      std::to_string(m_.accessors[static_cast<size_t>(accessor)].count) + " elements but POSITION has " +
                      std::to_string(n) + " (glTF 2.0: a morph target's accessors hold one element per vertex)");
      else if (attribute != "POSITION" && attribute != "NORMAL" && attribute != "TANGENT" && t < weights.size() &&
               weights[t] != 0.0)
        warn(who + ": morph target " + std::to_string(t) + " " + attribute + " is not used by spadgen (its POSITION and "
             "NORMAL are); the base " + attribute + " is");
  const auto morph = [&](const char* attribute, std::vector<double>& values) {
    for (size_t t = 0; t < p.targets.size() && t < weights.size(); ++t) {
      const auto it = p.targets[t].find(attribute);
      if (weights[t] == 0.0 || it == p.targets[t].end()) continue;
      check_component(it->second, who, attribute, true);
      size_t count = 0;
      int c = 0;
      const std::string target = who + " morph target " + std::to_string(t) + " " + attribute;
      const std::vector<double> d = read_accessor(it->second, target, {TINYGLTF_TYPE_VEC3}, &count, &c);
      if (count != n) fail(who, "morph target " + std::to_string(t) + " " + attribute + " has " + std::to_string(count) +
                                    " elements but POSITION has " + std::to_string(n));
      for (size_t v = 0; v < values.size(); ++v) values[v] += weights[t] * d[v];
    }
  };
  morph("POSITION", pos);
  const std::vector<glm::dmat4> skinned = gn.skin >= 0 ? skin_matrices(node, p, n, who) : std::vector<glm::dmat4>{};
  std::vector<glm::dvec3> world_pos(n);
  glm::dvec3 lo(std::numeric_limits<double>::infinity()), hi(-std::numeric_limits<double>::infinity());
  for (size_t v = 0; v < n; ++v) {
    const glm::dvec4 w = (skinned.empty() ? world : skinned[v]) * glm::dvec4(pos[3 * v], pos[3 * v + 1], pos[3 * v + 2], 1.0);
    world_pos[v] = glm::dvec3(w);
    check_world(world_pos[v], who, "POSITION element " + std::to_string(v));
    lo = glm::min(lo, world_pos[v]), hi = glm::max(hi, world_pos[v]);
  }
  // Where the vertices are (a skinned mesh's come from its joints, not its node).
  if (n > 0) out.offset = glm::round(0.5 * (lo + hi) / kMeshOffsetGridM) * kMeshOffsetGridM;
  out.positions.resize(n);
  for (size_t v = 0; v < n; ++v) out.positions[v] = glm::vec3(world_pos[v] - out.offset);
  const glm::dmat3 normal_matrix = glm::transpose(glm::inverse(glm::dmat3(world)));
  if (auto it = p.attributes.find("NORMAL"); it != p.attributes.end()) {
    check_component(it->second, who, "NORMAL", false);
    std::vector<double> nor = read_accessor(it->second, who + " NORMAL", {TINYGLTF_TYPE_VEC3}, &k, &comps);
    if (k != n) fail(who, "NORMAL has " + std::to_string(k) + " elements but POSITION has " + std::to_string(n));
    morph("NORMAL", nor);
    out.normals.resize(n);
    for (size_t v = 0; v < n; ++v) {
      glm::dmat3 nm = normal_matrix;
      if (!skinned.empty()) {  // a vertex without weights (the specification asks for a sum of 1) keeps no normal
        const glm::dmat3 m3(skinned[v]);
        const double det = glm::determinant(m3);
        nm = std::abs(det) > 1e-300 && std::isfinite(det) ? glm::transpose(glm::inverse(m3)) : glm::dmat3(0.0);
      }
      const glm::dvec3 wn = nm * glm::dvec3(nor[3 * v], nor[3 * v + 1], nor[3 * v + 2]);
      const double len = glm::length(wn);
      // A zero normal in the file stays zero: the renderer falls back to the geometric normal.
      out.normals[v] = len > 0 ? glm::vec3(wn / len) : glm::vec3(0.0f);
    }
  }
  // Only the set the material's base colour texture reads is kept (and checked): spadgen samples no other
  // texture, and a quantized set an occlusion or normal map reads, beyond +-4096 before its own transform,
  // would have refused the file.
  const int read_set = p.material >= 0 && static_cast<size_t>(p.material) < scene_.materials.size() &&
                               scene_.materials[static_cast<size_t>(p.material)].base_color_texture >= 0
                           ? scene_.materials[static_cast<size_t>(p.material)].base_color_texcoord
                           : -1;
  for (int set = 0; set < 2; ++set) {
    const std::string key = "TEXCOORD_" + std::to_string(set);
    auto it = p.attributes.find(key);
    if (it == p.attributes.end()) continue;
    check_component(it->second, who, key, false);
    if (set != read_set) continue;
    std::vector<double> uv = read_accessor(it->second, who + " " + key, {TINYGLTF_TYPE_VEC2}, &k, &comps);
    if (k != n) fail(who, key + " has " + std::to_string(k) + " elements but POSITION has " + std::to_string(n));
    // the set the material's base colour texture reads, through its KHR_texture_transform
    if (const auto tt = uv_transform_.find(p.material); tt != uv_transform_.end()) {
      const std::array<double, 6>& m = tt->second;
      for (size_t v = 0; v + 1 < uv.size(); v += 2) {
        const double u0 = uv[v], v0 = uv[v + 1];
        uv[v] = m[0] * u0 + m[1] * v0 + m[2];
        uv[v + 1] = m[3] * u0 + m[4] * v0 + m[5];
      }
    }
    for (size_t v = 0; v < uv.size(); ++v)
      if (!(std::abs(uv[v]) <= kMaxTexcoord))
        fail(who, key + " element " + std::to_string(v / 2) + " has the value " + num(uv[v]) + ", expected texture "
                  "coordinates within +-" + num(kMaxTexcoord) + " (beyond, a float no longer resolves a texel)");
    std::vector<glm::vec2>& dst = set == 0 ? out.texcoords0 : out.texcoords1;
    dst.resize(n);
    for (size_t v = 0; v < n; ++v) dst[v] = glm::vec2(glm::dvec2(uv[2 * v], uv[2 * v + 1]));
  }

  // COLOR_0 multiplies the base colour (glTF 2.0 3.9.2); its alpha is not used (surfaces are opaque).
  if (auto it = p.attributes.find("COLOR_0"); it != p.attributes.end()) {
    check_component(it->second, who, "COLOR_0", false);
    int cc = 0;
    const std::vector<double> col = read_accessor(it->second, who + " COLOR_0", {TINYGLTF_TYPE_VEC3, TINYGLTF_TYPE_VEC4}, &k, &cc);
    if (k != n) fail(who, "COLOR_0 has " + std::to_string(k) + " elements but POSITION has " + std::to_string(n));
    for (size_t v = 0; v < col.size(); ++v)
      if (!(col[v] >= 0.0 && col[v] <= 1.0))
        fail(who, "COLOR_0 element " + std::to_string(v / size_t(cc)) + " has the value " + num(col[v]) +
                      ", expected a colour within [0, 1] (glTF 2.0: linear RGB or RGBA)");
    out.colors0.resize(n);
    for (size_t v = 0; v < n; ++v)
      out.colors0[v] = glm::vec3(glm::dvec3(col[size_t(cc) * v], col[size_t(cc) * v + 1], col[size_t(cc) * v + 2]));
  }

  if (out.material >= 0) {
    const Material& mat = scene_.materials[static_cast<size_t>(out.material)];
    if (mat.base_color_texture >= 0 && mat.base_color_texcoord <= 1 &&
        (mat.base_color_texcoord == 0 ? out.texcoords0 : out.texcoords1).empty())
      warn(who + ": its material's baseColorTexture uses TEXCOORD_" + std::to_string(mat.base_color_texcoord) +
           ", which the primitive does not have; the texture is not used on it (the base colour factor is)");
  }

  std::vector<uint32_t> idx;
  if (p.indices >= 0) {
    if (static_cast<size_t>(p.indices) < m_.accessors.size()) {
      const tinygltf::Accessor& a = m_.accessors[static_cast<size_t>(p.indices)];
      const int ct = a.componentType;
      if (ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_BYTE && ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT &&
          ct != TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT)
        fail(who, std::string("indices accessor ") + std::to_string(p.indices) + " has componentType " +
                      component_name(ct) + "; indices must be UNSIGNED_BYTE, UNSIGNED_SHORT or UNSIGNED_INT");
      // (read as fractions of the largest value, every index was 0: nothing rendered, and nothing said why)
      if (a.normalized)
        fail(who, std::string("indices accessor ") + std::to_string(p.indices) + " is normalized; indices are vertex "
                      "numbers, not normalized (glTF 2.0: an unsigned integer SCALAR accessor; remove \"normalized\": true)");
    }
    const std::vector<double> raw = read_accessor(p.indices, who + " indices", {TINYGLTF_TYPE_SCALAR}, &k, &comps);
    idx.resize(k);
    for (size_t j = 0; j < k; ++j) {
      if (raw[j] >= static_cast<double>(n))
        fail(who, "index " + std::to_string(static_cast<uint64_t>(raw[j])) + " at position " + std::to_string(j) +
                      " of accessor " + std::to_string(p.indices) + " is out of range of the " + std::to_string(n) +
                      " vertices");
      idx[j] = static_cast<uint32_t>(raw[j]);
    }
  } else {
    if (n > std::numeric_limits<uint32_t>::max()) fail(who, "too many vertices");
    idx.resize(n);
    for (size_t j = 0; j < n; ++j) idx[j] = static_cast<uint32_t>(j);
  }

  if (p.mode == TINYGLTF_MODE_TRIANGLES) {
    if (idx.size() % 3 != 0)
      warn(who + ": " + std::to_string(idx.size()) + (p.indices >= 0 ? " indices are" : " vertices (no indices) are") +
           " not a multiple of 3; the last " + std::to_string(idx.size() % 3) + " are ignored");
    out.indices.assign(idx.begin(), idx.end() - static_cast<std::ptrdiff_t>(idx.size() % 3));
  } else {
    // Strips and fans become triangle lists with the glTF winding (specification 3.7.2.1);
    // degenerate triangles (used to join strips) are dropped.
    for (size_t t = 0; t + 2 < idx.size(); ++t) {
      uint32_t a, b, c;
      if (p.mode == TINYGLTF_MODE_TRIANGLE_STRIP) {
        a = idx[t];
        b = idx[t + 1 + t % 2];
        c = idx[t + 2 - t % 2];
      } else {
        a = idx[t + 1];
        b = idx[t + 2];
        c = idx[0];
      }
      if (a == b || b == c || a == c) continue;
      out.indices.insert(out.indices.end(), {a, b, c});
    }
  }
  // A mirroring transform turns counter-clockwise triangles clockwise: swap to keep the front side. A skinned
  // mesh's transform is its skin's, per vertex (glTF ignores its node's): the sum of the triangle's three.
  const bool mirrored = glm::determinant(glm::dmat3(world)) < 0;
  for (size_t t = 0; t + 2 < out.indices.size(); t += 3) {
    const uint32_t* v = &out.indices[t];
    if (skinned.empty() ? mirrored
                        : glm::determinant(glm::dmat3(skinned[v[0]]) + glm::dmat3(skinned[v[1]]) + glm::dmat3(skinned[v[2]])) < 0)
      std::swap(out.indices[t + 1], out.indices[t + 2]);
  }
  if (out.indices.empty()) {
    warn(who + ": has no triangles; skipped");
    return;
  }
  // Triangles that all have no area are not seen: said, with the likely cause (a POSITION accessor without a
  // bufferView reads as zeros; the mesh vanished, and the run said only that nothing was in view: an
  // auditor's find).
  bool flat = true;
  for (size_t t = 0; flat && t + 2 < out.indices.size(); t += 3) {
    const glm::vec3 a = out.positions[out.indices[t]], b = out.positions[out.indices[t + 1]], c = out.positions[out.indices[t + 2]];
    flat = glm::cross(b - a, c - a) == glm::vec3(0.0f);
  }
  if (flat) {
    const tinygltf::Accessor& a = m_.accessors[static_cast<size_t>(pos_it->second)];
    warn(who + ": none of its " + std::to_string(out.indices.size() / 3) + " triangles has an area (their vertices " +
         "coincide or lie on a line), so it is not seen" +
         (a.bufferView < 0 && !a.sparse.isSparse
              ? " (its POSITION " + label("accessor", static_cast<size_t>(pos_it->second), a.name) +
                    " has no bufferView: glTF 2.0 reads it as zeros)"
              : std::string()));
  }
  scene_.meshes.push_back(std::move(out));
}

// The name a scene file chooses a camera or light of node `node` by: the node's (object_name), else the camera's or
// light's own, else the node's generated name, as an unnamed mesh's node has ("node3": one of no name could not be
// chosen at all).
std::string Loader::chosen_name(size_t node, const std::string& own) const {
  if (!m_.nodes[node].name.empty()) return object_name(node);
  return !own.empty() ? own : "node" + std::to_string(node);
}

// Blender's exporter puts each camera and light on an extra child node "<object>_Orientation"; users
// know the object's name from the outliner, so that is the name the scene file refers to.
std::string Loader::object_name(size_t node) const {
  static const std::string suffix = "_Orientation";
  const std::string& n = m_.nodes[node].name;
  if (n.size() > suffix.size() && n.compare(n.size() - suffix.size(), suffix.size(), suffix) == 0 && parent_[node] >= 0) {
    const std::string& parent = m_.nodes[static_cast<size_t>(parent_[node])].name;
    if (parent == n.substr(0, n.size() - suffix.size())) return parent;
  }
  return n;
}

void Loader::load_camera(size_t node, const glm::dmat4& world) {
  const tinygltf::Node& n = m_.nodes[node];
  if (static_cast<size_t>(n.camera) >= m_.cameras.size())
    fail(node_label(m_, node), "camera " + std::to_string(n.camera) + " does not exist (the file has " +
                                   std::to_string(m_.cameras.size()) + " cameras)");
  const tinygltf::Camera& c = m_.cameras[static_cast<size_t>(n.camera)];
  const std::string who = label("camera", static_cast<size_t>(n.camera), c.name) + " (" + node_label(m_, node) + ")";
  if (c.type == "orthographic") {
    warn(who + ": orthographic cameras are not used by spadgen; skipped");
    scene_.orthographic_cameras.push_back(chosen_name(node, c.name));
    return;
  }
  if (c.type != "perspective") fail(who, "type " + quoted(c.type) + " is neither perspective nor orthographic");
  const double yfov = c.perspective.yfov;
  if (!(yfov > 0 && yfov < kPi)) fail(who, "yfov " + num(yfov) + " must lie in (0, pi) radians");
  const double aspect = c.perspective.aspectRatio;
  if (!(aspect >= 0) || !std::isfinite(aspect))
    fail(who, "aspectRatio " + num(aspect) + " must be > 0");
  Camera cam;
  cam.name = chosen_name(node, c.name);
  cam.where = who;
  cam.yfov_rad = yfov;
  cam.aspect_ratio = aspect;
  // Cameras take position and orientation from their node; a scale there (allowed, but meaningless
  // for a pinhole) is removed so the renderer gets a rigid transform.
  glm::dmat4 rigid = world;
  for (int k = 0; k < 3; ++k) {
    const double len = glm::length(glm::dvec3(world[k]));
    if (!(len > 1e-12)) fail(who, "its node's world transform has a zero scale");
    rigid[k] = glm::dvec4(glm::dvec3(world[k]) / len, 0.0);
  }
  if (glm::determinant(glm::dmat3(rigid)) < 0) {
    warn(who + ": its node's transform mirrors; the camera's x axis is flipped back");
    rigid[0] = -rigid[0];
  }
  check_world(glm::dvec3(rigid[3]), who, "the camera");
  cam.world_from_camera = rigid;
  scene_.cameras.push_back(std::move(cam));
}

void Loader::load_light(size_t node, const glm::dmat4& world) {
  const tinygltf::Node& n = m_.nodes[node];
  const tinygltf::Value& ext = n.extensions.at("KHR_lights_punctual");
  const std::string nwho = node_label(m_, node);
  if (!ext.IsObject() || !ext.Has("light") || !ext.Get("light").IsInt())
    fail(nwho, "KHR_lights_punctual has no integer 'light'");
  const int li = ext.Get("light").GetNumberAsInt();
  if (li < 0 || static_cast<size_t>(li) >= m_.lights.size())
    fail(nwho, "KHR_lights_punctual light " + std::to_string(li) + " does not exist (the file has " +
                   std::to_string(m_.lights.size()) + " lights)");
  const tinygltf::Light& g = m_.lights[static_cast<size_t>(li)];
  const std::string who = label("light", static_cast<size_t>(li), g.name) + " (" + nwho + ")";
  Light l;
  l.name = chosen_name(node, g.name);
  l.where = who;
  if (g.type == "point")
    l.type = Light::Type::Point;
  else if (g.type == "spot")
    l.type = Light::Type::Spot;
  else if (g.type == "directional")
    l.type = Light::Type::Directional;
  else
    fail(who, "type " + quoted(g.type) + " is not point, spot or directional");
  const glm::dvec3 color = vec3(g.color, {1, 1, 1}, who, "color");
  if (!(color.x >= 0 && color.y >= 0 && color.z >= 0 && color.x <= 1 && color.y <= 1 && color.z <= 1))
    fail(who, "color [" + num(color.x) + ", " + num(color.y) + ", " + num(color.z) +
                  "] must lie in [0, 1] (glTF 2.0; the intensity carries the brightness)");
  l.color = glm::vec3(color);
  if (!(g.intensity >= 0) || !std::isfinite(g.intensity)) fail(who, "intensity " + num(g.intensity) + " must be >= 0");
  l.intensity = g.intensity;
  if (!(g.range >= 0) || !std::isfinite(g.range)) fail(who, "range " + num(g.range) + " must be > 0");
  l.range = g.range;
  if (g.range > 0)
    warn(who + ": range " + num(g.range) + " m is not used; the light falls off as the inverse square of the distance "
               "without a cutoff");
  if (l.type == Light::Type::Spot) {
    const double inner = g.spot.innerConeAngle, outer = g.spot.outerConeAngle;
    if (!(inner >= 0 && inner < outer && outer <= kPi / 2 + 1e-9))
      fail(who, "spot cone angles inner " + num(inner) + " and outer " + num(outer) +
                    " must satisfy 0 <= inner < outer <= pi/2");
    l.inner_cone_rad = inner;
    l.outer_cone_rad = outer;
  }
  l.position = glm::dvec3(world[3]);
  if (l.type != Light::Type::Directional) check_world(l.position, who, "the light");
  const glm::dvec3 dir = glm::dmat3(world) * glm::dvec3(0, 0, -1);
  const double len = glm::length(dir);
  if (!(len > 1e-12)) fail(who, "its node's world transform has a zero scale");
  l.direction = dir / len;
  scene_.lights.push_back(std::move(l));
}

void Loader::load(const std::string& scene_name) {
  check_extensions();
  check_unused_features();
  check_hierarchy();
  const std::vector<int> roots = pick_roots(scene_name);
  resolve_edits();
  scene_.nodes.resize(m_.nodes.size());
  for (size_t i = 0; i < m_.nodes.size(); ++i) scene_.nodes[i].name = m_.nodes[i].name, scene_.nodes[i].parent = parent_[i];
  load_materials();
  for (int r : roots) visit(r, glm::dmat4(1.0));
  warn_unused_edits();
  check_volumes();
}

// A volume material (transmission and KHR_materials_volume thickness > 0) makes a medium of what its mesh
// encloses: a ray that enters through a front face travels in it until it leaves through a back face. Its
// node's triangles must enclose a solid, with outward faces. An open sheet (a plane exported with a volume
// thickness) let rays in that never left: the wall behind it was seen through 0.5 m of glass (+1.7 ns); an
// inside-out box was a medium outside and air inside. Each connected piece of a node's triangles that holds
// a volume's faces is checked: every edge shared by two faces (else open), each edge crossed once each way
// (else faces flipped within it), a volume enclosed (else a sheet with faces on both sides), and a positive
// one (else inward). Vertices are matched by position over all of the node's primitives (exporters split
// vertices at seams; a solid may have faces of other materials): exactly when they share one offset (Mesh::offset),
// else within 4 float steps of the largest position (primitives far from the origin round their positions
// about their own offsets: a closed box 31 m away was warned open). Sorted arrays, not maps: a glass
// sphere of a million triangles is checked in about 0.6 s and 100 MB, freed before rendering (a pane of
// two million, all of a face's vertices at one x, 1.6 s).
namespace {
std::string volume_text(double m3) {
  char buf[48];
  std::snprintf(buf, sizeof buf, "%.3g cm^3", m3 * 1e6);
  return buf;
}
}  // namespace

void Loader::check_volumes() {
  const auto is_volume = [&](int material) { return material >= 0 && scene_.materials[static_cast<size_t>(material)].bounds_medium(); };
  std::map<int, std::vector<size_t>> meshes_of_node;  // nodes with a volume primitive -> all their meshes
  std::set<int> volume_nodes;
  for (size_t i = 0; i < scene_.meshes.size(); ++i) {
    meshes_of_node[scene_.meshes[i].gltf_node].push_back(i);
    if (is_volume(scene_.meshes[i].material)) volume_nodes.insert(scene_.meshes[i].gltf_node);
  }
  for (const int node : volume_nodes) {
    const std::vector<size_t>& meshes = meshes_of_node[node];
    // Every vertex's world position, and an id per distinct position.
    struct Vertex {
      glm::dvec3 p;
      uint32_t index;  // into the node's vertices (its meshes in order)
    };
    std::vector<Vertex> vs;
    std::vector<size_t> first_vertex;  // of each mesh
    bool one_offset = true;
    float largest = 0.0f;
    for (const size_t mi : meshes) {
      const Mesh& m = scene_.meshes[mi];
      first_vertex.push_back(vs.size());
      one_offset = one_offset && m.offset == scene_.meshes[meshes.front()].offset;
      for (const glm::vec3& q : m.positions) {
        vs.push_back({m.offset + glm::dvec3(q), static_cast<uint32_t>(vs.size())});
        largest = std::max({largest, std::abs(q.x), std::abs(q.y), std::abs(q.z)});
      }
    }
    const double tolerance = one_offset ? 0.0 : 4.0 * double(largest) * double(std::numeric_limits<float>::epsilon());
    std::vector<uint32_t> id(vs.size());
    uint32_t next = 0;
    if (tolerance == 0.0) {
      // equal positions side by side once sorted
      std::vector<Vertex> sorted = vs;
      std::sort(sorted.begin(), sorted.end(), [](const Vertex& a, const Vertex& b) {
        return a.p.x != b.p.x ? a.p.x < b.p.x : a.p.y != b.p.y ? a.p.y < b.p.y : a.p.z < b.p.z;
      });
      for (size_t i = 0; i < sorted.size(); ++i) id[sorted[i].index] = i > 0 && sorted[i].p == sorted[i - 1].p ? next - 1 : next++;
    } else {
      // within the tolerance: a grid of cells of 8 tolerances, a position looked up in the cells within the
      // tolerance of it (one, unless it lies near a cell's side)
      const double cell_size = 8.0 * tolerance;
      const auto cell = [&](const glm::dvec3& p) {
        return std::array<int64_t, 3>{static_cast<int64_t>(std::floor(p.x / cell_size)), static_cast<int64_t>(std::floor(p.y / cell_size)),
                                      static_cast<int64_t>(std::floor(p.z / cell_size))};
      };
      std::map<std::array<int64_t, 3>, std::vector<uint32_t>> cells;  // cell -> the first vertex of each id in it
      for (const Vertex& v : vs) {
        const std::array<int64_t, 3> lo = cell(v.p - glm::dvec3(tolerance)), hi = cell(v.p + glm::dvec3(tolerance));
        bool found = false;
        for (int64_t x = lo[0]; x <= hi[0] && !found; ++x)
          for (int64_t y = lo[1]; y <= hi[1] && !found; ++y)
            for (int64_t z = lo[2]; z <= hi[2] && !found; ++z)
              if (const auto it = cells.find({x, y, z}); it != cells.end())
                for (const uint32_t w : it->second)
                  if (std::abs(vs[w].p.x - v.p.x) <= tolerance && std::abs(vs[w].p.y - v.p.y) <= tolerance &&
                      std::abs(vs[w].p.z - v.p.z) <= tolerance) {
                    id[v.index] = id[w], found = true;
                    break;
                  }
        if (!found) id[v.index] = next++, cells[cell(v.p)].push_back(v.index);
      }
    }
    struct Tri {
      uint32_t v[3];
      size_t mesh, at;  // the node's mesh, and the triangle's first index in it
      bool volume;
    };
    std::vector<Tri> tris;
    std::set<std::string> materials;
    for (size_t k = 0; k < meshes.size(); ++k) {
      const Mesh& m = scene_.meshes[meshes[k]];
      const bool volume = is_volume(m.material);
      if (volume) materials.insert(label("material", static_cast<size_t>(m.material), scene_.materials[static_cast<size_t>(m.material)].name));
      for (size_t t = 0; t + 2 < m.indices.size(); t += 3) {
        Tri tri{{}, k, t, volume};
        for (int c = 0; c < 3; ++c) tri.v[c] = id[first_vertex[k] + m.indices[t + size_t(c)]];
        if (tri.v[0] != tri.v[1] && tri.v[1] != tri.v[2] && tri.v[0] != tri.v[2]) tris.push_back(tri);  // no area
      }
    }
    // Half-edges sorted by their undirected edge (low id << 32 | high id): an edge's faces side by side.
    struct Half {
      uint64_t edge;
      uint32_t tri;
      bool forward;  // low -> high
    };
    std::vector<Half> halves;
    halves.reserve(3 * tris.size());
    for (size_t t = 0; t < tris.size(); ++t)
      for (int c = 0; c < 3; ++c) {
        const uint32_t u = tris[t].v[c], v = tris[t].v[(c + 1) % 3];
        halves.push_back({uint64_t{std::min(u, v)} << 32 | std::max(u, v), static_cast<uint32_t>(t), u < v});
      }
    std::sort(halves.begin(), halves.end(), [](const Half& a, const Half& b) { return a.edge < b.edge; });
    const auto each_edge = [&](auto&& f) {  // f(its first half, the end of its halves)
      for (size_t i = 0; i < halves.size();) {
        size_t j = i + 1;
        while (j < halves.size() && halves[j].edge == halves[i].edge) ++j;
        f(i, j);
        i = j;
      }
    };
    // Connected pieces (faces sharing an edge), by union-find.
    std::vector<uint32_t> parent(tris.size());
    for (size_t t = 0; t < tris.size(); ++t) parent[t] = static_cast<uint32_t>(t);
    const auto root = [&](uint32_t t) {
      while (parent[t] != t) t = parent[t] = parent[parent[t]];
      return t;
    };
    each_edge([&](size_t i, size_t j) {
      for (size_t k = i + 1; k < j; ++k) parent[root(halves[k].tri)] = root(halves[i].tri);
    });
    struct Piece {
      bool volume = false, has_o = false;
      size_t open = 0, flipped = 0;
      double six_v = 0.0;
      glm::dvec3 o{0.0}, lo{std::numeric_limits<double>::infinity()}, hi{-std::numeric_limits<double>::infinity()};
    };
    std::map<uint32_t, Piece> pieces;
    each_edge([&](size_t i, size_t j) {
      Piece& pc = pieces[root(halves[i].tri)];
      size_t forward = 0;
      for (size_t k = i; k < j; ++k) forward += halves[k].forward;
      pc.open += j - i != 2;
      pc.flipped += j - i == 2 && forward != 1;
    });
    for (size_t t = 0; t < tris.size(); ++t) {
      Piece& pc = pieces[root(static_cast<uint32_t>(t))];
      const Mesh& m = scene_.meshes[meshes[tris[t].mesh]];
      glm::dvec3 p[3];
      for (int c = 0; c < 3; ++c) {
        p[c] = vs[first_vertex[tris[t].mesh] + m.indices[tris[t].at + size_t(c)]].p;
        pc.lo = glm::min(pc.lo, p[c]), pc.hi = glm::max(pc.hi, p[c]);
      }
      if (!pc.has_o) pc.o = p[0], pc.has_o = true;
      pc.six_v += glm::dot(p[0] - pc.o, glm::cross(p[1] - pc.o, p[2] - pc.o));
      pc.volume = pc.volume || tris[t].volume;
    }
    std::string mats;
    for (const std::string& m : materials) mats += (mats.empty() ? "" : ", ") + m;
    const std::string who = node_label(m_, static_cast<size_t>(node)) + " (" + mats + ": transmission and a volume thickness)";
    // One warning per problem, over the node's connected pieces (one per piece repeated the same text, which
    // the warnings' de-duplication merged: six open pieces of 128 edges were told as two of 32).
    size_t n_pieces = 0, open_pieces = 0, open_edges = 0, flipped_pieces = 0, flipped_edges = 0, flat = 0, inward = 0;
    double inward_v = 0.0;
    for (const auto& [r, pc] : pieces) {
      if (!pc.volume) continue;
      ++n_pieces;
      const double d = glm::length(pc.hi - pc.lo);
      if (pc.open > 0) {
        ++open_pieces, open_edges += pc.open;
      } else if (pc.flipped > 0) {
        ++flipped_pieces, flipped_edges += pc.flipped;
      } else if (std::abs(pc.six_v) / 6.0 <= 1e-9 * d * d * d) {
        ++flat;  // closed and consistent: the enclosed volume's sign says whether the faces point out (divergence theorem)
      } else if (pc.six_v < 0.0) {
        ++inward, inward_v += pc.six_v / 6.0;
      }
    }
    const auto of = [n_pieces](size_t k) {
      return n_pieces == 1 ? std::string() : std::to_string(k) + " of its " + std::to_string(n_pieces) + " connected pieces: ";
    };
    if (open_pieces > 0)
      warn(who + ": its triangles do not enclose a solid (" + of(open_pieces) + std::to_string(open_edges) +
           (open_edges == 1 ? " edge is" : " edges are") +
           " not shared by exactly two faces): a volume's mesh is the boundary of its medium, and a ray entering it "
           "through an open surface travels in it until it meets another back face, the surfaces behind included; close "
           "the mesh (a plate as a box of its thickness), or set thicknessFactor 0 for a thin sheet");
    if (flipped_pieces > 0)
      warn(who + ": its faces are not consistently oriented (" + of(flipped_pieces) + std::to_string(flipped_edges) +
           (flipped_edges == 1 ? " edge" : " edges") +
           " between faces of opposite windings): where a face points in, a ray changes medium the wrong way; recalculate "
           "its normals outside (in Blender: Mesh > Normals > Recalculate Outside)");
    if (flat > 0)
      warn(who + ": its triangles enclose no volume (" + (n_pieces == 1 ? std::string("a sheet") : of(flat) + "sheets") +
           " with faces on both sides?): a volume's mesh is the boundary of its medium; make it a solid (a plate as a box "
           "of its thickness), or set thicknessFactor 0 for a thin sheet");
    if (inward > 0)
      warn(who + ": its faces point inward (" + of(inward) + "the enclosed volume is negative, " + volume_text(inward_v) +
           "): the medium is taken as outside the mesh and air inside; reverse its triangles' winding (in Blender: "
           "Mesh > Normals > Flip, or Recalculate Outside)");
  }
}

// glTF URIs are percent-encoded ("my%20scene.bin").
std::string uri_decode(const std::string& uri) {
  std::string out;
  for (size_t i = 0; i < uri.size(); ++i) {
    if (uri[i] == '%' && i + 2 < uri.size() && std::isxdigit(static_cast<unsigned char>(uri[i + 1])) &&
        std::isxdigit(static_cast<unsigned char>(uri[i + 2]))) {
      out += static_cast<char>(std::stoi(uri.substr(i + 1, 2), nullptr, 16));
      i += 2;
    } else {
      out += uri[i];
    }
  }
  return out;
}

// "3c 21 44 4f ..." of what a file starts with, shown as text where it is printable.
std::string start_of(const std::string& bytes) {
  std::string shown;
  for (size_t i = 0; i < bytes.size() && i < 24; ++i) {
    const auto c = static_cast<unsigned char>(bytes[i]);
    if (c == '\n' || c == '\r' || c == '\t') shown += ' ';
    else if (c >= 32 && c < 127) shown += static_cast<char>(c);
    else {
      char hex[8];
      std::snprintf(hex, sizeof hex, "\\x%02x", c);
      shown += hex;
    }
  }
  return "'" + shown + (bytes.size() > 24 ? "...'" : "'");
}

// The JSON of a .gltf or .glb, after recognising which it is; anything else is named for what it looks
// like, before tinygltf sees it.
// `bin_bytes`, when given, is set to the length of a .glb's BIN chunk, or -1 when it has none (and for a .gltf).
// `unknown_chunk`, when given, is set to the type of a .glb's second chunk when that is neither BIN nor cut
// short (glTF 2.0: readers ignore chunks of unknown types; it and what follows it are not read), else left empty.
std::string gltf_json(const std::string& path, const std::string& bytes, bool* binary, int64_t* bin_bytes = nullptr,
                      std::string* unknown_chunk = nullptr) {
  *binary = bytes.size() >= 4 && std::memcmp(bytes.data(), "glTF", 4) == 0;
  if (bin_bytes) *bin_bytes = -1;
  if (unknown_chunk) unknown_chunk->clear();
  if (*binary) {
    // GLB: magic, version, length, then the JSON chunk's length, type ("JSON") and content.
    uint32_t version = 0, length = 0, chunk = 0, type = 0;
    if (bytes.size() >= 20) {
      std::memcpy(&version, bytes.data() + 4, 4);
      std::memcpy(&length, bytes.data() + 8, 4);
      std::memcpy(&chunk, bytes.data() + 12, 4);
      std::memcpy(&type, bytes.data() + 16, 4);
    }
    const std::string invalid = path + ": not a valid binary glTF (.glb): ";
    if (bytes.size() >= 20 && version == 2 && length > bytes.size())
      throw Error(invalid + "its header gives a length of " + std::to_string(length) + " bytes but the file holds " +
                  std::to_string(bytes.size()) + " (cut short, as by an interrupted download or copy?)");
    if (bytes.size() >= 20 && version != 2)
      throw Error(invalid + "its header gives version " + std::to_string(version) + "; expected version 2");
    if (bytes.size() < 20 || length < 20)
      throw Error(invalid + "expected a 12-byte header and a JSON chunk's 8-byte header; the " +
                  (bytes.size() < 20 ? "file holds " + std::to_string(bytes.size()) : "header gives a length of " + std::to_string(length)) +
                  " bytes");
    if (type != 0x4E4F534Au)
      throw Error(invalid + "its first chunk is of type " + start_of(bytes.substr(16, 4)) + "; expected 'JSON'");
    if (chunk > length - 20)
      throw Error(invalid + "its JSON chunk gives a length of " + std::to_string(chunk) + " bytes but the file's length (" +
                  std::to_string(length) + " in its header) leaves " + std::to_string(length - 20) + " after the chunk's header");
    // The BIN chunk, when the length leaves room for one: its 8-byte header and its bytes within the length.
    // (tinygltf 2.7 leaves the chunk's header out of that bound, and read up to 8 bytes past a file cut short.)
    const uint64_t json_end = 20ull + chunk;
    if (json_end < length) {
      if (json_end + 8 > length)
        throw Error(invalid + std::to_string(length - json_end) + " bytes follow the JSON chunk, too few for a chunk's 8-byte "
                    "header; expected a BIN chunk or nothing after it");
      uint32_t bin = 0, bin_type = 0;
      std::memcpy(&bin, bytes.data() + json_end, 4);
      std::memcpy(&bin_type, bytes.data() + json_end + 4, 4);
      if (bin_type != 0x004E4942u) {  // "BIN\0"
        // A chunk of another type that fits the file is one a reader ignores (glTF 2.0, 4.4.3.1); one that does
        // not is more likely a JSON chunk's length gone wrong.
        if (json_end + 8 + bin <= length) {
          if (unknown_chunk) *unknown_chunk = start_of(bytes.substr(json_end + 4, 4));
          return bytes.substr(20, chunk);
        }
        throw Error(invalid + "after its JSON chunk (" + std::to_string(chunk) + " bytes) comes no BIN chunk's header but " +
                    start_of(bytes.substr(json_end, 8)) + "; expected a BIN chunk (type 'BIN\\0') or nothing (is the JSON "
                    "chunk's length right?)");
      }
      if (json_end + 8 + bin > length)
        throw Error(invalid + "its BIN chunk gives a length of " + std::to_string(bin) + " bytes but " +
                    std::to_string(length - json_end - 8) + " follow its header (cut short, as by an interrupted download or copy?)");
      if (bin_bytes) *bin_bytes = bin;
    }
    return bytes.substr(20, chunk);
  }
  size_t i = bytes.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;  // a UTF-8 byte order mark
  while (i < bytes.size() && std::isspace(static_cast<unsigned char>(bytes[i]))) ++i;
  if (i == bytes.size()) throw Error(path + ": the glTF file is empty");
  if (bytes[i] != '{') {
    std::string lower;
    for (size_t k = i; k < bytes.size() && k < i + 512; ++k) lower += static_cast<char>(std::tolower(static_cast<unsigned char>(bytes[k])));
    const bool html = lower.rfind("<!doctype html", 0) == 0 || lower.find("<html") != std::string::npos;
    throw Error(path + ": not a glTF file: it starts with " + start_of(bytes.substr(i)) +
                (html ? ", an HTML page (a web page saved instead of the file it links to?)" : "") +
                "; expected JSON starting with '{' (.gltf) or the bytes 'glTF' (.glb)");
  }
  return bytes;
}

// The types of the glTF 2.0 properties spadgen reads, checked on the file's JSON: tinygltf reads a
// property of the wrong type as absent and takes its default ("mesh": "0" left a node without its mesh,
// "scale": "big" made it 1, a byteOffset of -4 or 2.5 was read as 0). Only types and signs: what the
// values mean (indices in range, sizes that fit) the loader checks as it reads them.
enum class Want { Index, Offset, Count, IntCount, Stride, Integer, Number, Bool, String, Object, Numbers, Indices, Objects, IndexMap };
struct Rule {
  const char* key;
  Want want;
  size_t n = 0;  // Numbers: the length (0: any)
  const char* object = nullptr;  // Object, Objects: the rules of its properties (a key of gltf_rules())
};
const std::map<std::string, std::vector<Rule>>& gltf_rules() {
  static const std::map<std::string, std::vector<Rule>> rules = {
      {"accessor", {{"bufferView", Want::Index}, {"byteOffset", Want::Offset}, {"componentType", Want::Integer},
                    {"normalized", Want::Bool}, {"count", Want::Count}, {"type", Want::String}, {"max", Want::Numbers},
                    {"min", Want::Numbers}, {"sparse", Want::Object, 0, "sparse"}, {"name", Want::String}}},
      {"sparse", {{"count", Want::IntCount}, {"indices", Want::Object, 0, "sparse indices"}, {"values", Want::Object, 0, "sparse values"}}},
      {"sparse indices", {{"bufferView", Want::Index}, {"byteOffset", Want::Offset}, {"componentType", Want::Integer}}},
      {"sparse values", {{"bufferView", Want::Index}, {"byteOffset", Want::Offset}}},
      {"bufferView", {{"buffer", Want::Index}, {"byteOffset", Want::Offset}, {"byteLength", Want::Count},
                      {"byteStride", Want::Stride}, {"target", Want::Integer}, {"name", Want::String}}},
      {"buffer", {{"uri", Want::String}, {"byteLength", Want::Count}, {"name", Want::String}}},
      {"node", {{"camera", Want::Index}, {"children", Want::Indices}, {"skin", Want::Index}, {"matrix", Want::Numbers, 16},
                {"mesh", Want::Index}, {"rotation", Want::Numbers, 4}, {"scale", Want::Numbers, 3},
                {"translation", Want::Numbers, 3}, {"weights", Want::Numbers}, {"name", Want::String}}},
      {"mesh", {{"primitives", Want::Objects, 0, "primitive"}, {"weights", Want::Numbers}, {"name", Want::String}}},
      {"primitive", {{"attributes", Want::IndexMap}, {"indices", Want::Index}, {"material", Want::Index},
                     {"mode", Want::Integer}}},
      {"material", {{"pbrMetallicRoughness", Want::Object, 0, "pbrMetallicRoughness"}, {"normalTexture", Want::Object, 0, "texture info"},
                    {"occlusionTexture", Want::Object, 0, "texture info"}, {"emissiveTexture", Want::Object, 0, "texture info"},
                    {"emissiveFactor", Want::Numbers, 3}, {"alphaMode", Want::String}, {"alphaCutoff", Want::Number},
                    {"doubleSided", Want::Bool}, {"name", Want::String}}},
      {"pbrMetallicRoughness", {{"baseColorFactor", Want::Numbers, 4}, {"baseColorTexture", Want::Object, 0, "texture info"},
                                {"metallicFactor", Want::Number}, {"roughnessFactor", Want::Number},
                                {"metallicRoughnessTexture", Want::Object, 0, "texture info"}}},
      {"texture info", {{"index", Want::Index}, {"texCoord", Want::Index}, {"scale", Want::Number}, {"strength", Want::Number}}},
      {"texture", {{"sampler", Want::Index}, {"source", Want::Index}, {"name", Want::String}}},
      {"image", {{"uri", Want::String}, {"mimeType", Want::String}, {"bufferView", Want::Index}, {"name", Want::String}}},
      {"sampler", {{"magFilter", Want::Integer}, {"minFilter", Want::Integer}, {"wrapS", Want::Integer},
                   {"wrapT", Want::Integer}, {"name", Want::String}}},
      {"camera", {{"type", Want::String}, {"perspective", Want::Object, 0, "perspective"},
                  {"orthographic", Want::Object, 0, "orthographic"}, {"name", Want::String}}},
      {"perspective", {{"aspectRatio", Want::Number}, {"yfov", Want::Number}, {"zfar", Want::Number}, {"znear", Want::Number}}},
      {"orthographic", {{"xmag", Want::Number}, {"ymag", Want::Number}, {"zfar", Want::Number}, {"znear", Want::Number}}},
      {"scene", {{"nodes", Want::Indices}, {"name", Want::String}}},
      {"light", {{"type", Want::String}, {"color", Want::Numbers, 3}, {"intensity", Want::Number}, {"range", Want::Number},
                 {"spot", Want::Object, 0, "spot"}, {"name", Want::String}}},
      {"spot", {{"innerConeAngle", Want::Number}, {"outerConeAngle", Want::Number}}},
  };
  return rules;
}

// An integer written without a decimal point (tinygltf reads 0.0 as no value at all) in [lo, hi]: indices
// and enums within tinygltf's int; byte offsets, lengths and counts up to 2^53 (past what a file holds:
// the loader refuses them with its size).
bool gltf_integer(const nlohmann::json& v, double lo, double hi = 2147483647.0) {
  if (!v.is_number_integer()) return false;
  const double d = v.get<double>();
  return d >= lo && d <= hi;
}
constexpr double kMaxExact = 9007199254740992.0;

// What an index, offset or count must be, said for the value found: its bound when it is an integer past it
// (2^62 was told "an integer >= 1").
std::string integer_wanted(const nlohmann::json& v, int lo, const char* hi) {
  const std::string least = "an integer >= " + std::to_string(lo);
  if (v.is_number_float()) return least + ", written without a decimal point";
  if (v.is_number_integer() && v.get<double>() >= lo) return least + " and at most " + hi;
  return least;
}

void check_gltf_object(const std::string& path, const std::string& who, const nlohmann::json& o, const std::string& rules) {
  for (const Rule& r : gltf_rules().at(rules)) {
    const auto it = o.find(r.key);
    if (it == o.end()) continue;
    const nlohmann::json& v = *it;
    const std::string at = who + ": " + r.key;
    const auto refuse = [&](const std::string& expected) {
      std::string shown = v.dump();
      if (shown.size() > 40) shown = shown.substr(0, 37) + "...";
      throw Error(path + ": " + at + ": found " + shown + ", expected " + expected);
    };
    switch (r.want) {
      case Want::Index: if (!gltf_integer(v, 0)) refuse(integer_wanted(v, 0, "2147483647")); break;
      case Want::Offset: if (!gltf_integer(v, 0, kMaxExact)) refuse(integer_wanted(v, 0, "2^53")); break;
      case Want::Count: if (!gltf_integer(v, 1, kMaxExact)) refuse(integer_wanted(v, 1, "2^53")); break;
      // (a count tinygltf keeps in an int: 2^31 became -2147483648, and the message said so)
      case Want::IntCount: if (!gltf_integer(v, 1)) refuse(integer_wanted(v, 1, "2147483647")); break;
      // (glTF 2.0's bounds; tinygltf said "must be the multiple of 4" of 256, naming no bufferView)
      case Want::Stride:
        if (!gltf_integer(v, 4, 252) || v.get<int64_t>() % 4 != 0) refuse("a multiple of 4 from 4 to 252 (glTF 2.0's byteStride)");
        break;
      case Want::Integer: if (!gltf_integer(v, -2147483648.0)) refuse("an integer"); break;
      case Want::Number: if (!v.is_number()) refuse("a number"); break;
      case Want::Bool: if (!v.is_boolean()) refuse("true or false"); break;
      case Want::String: if (!v.is_string()) refuse("a string"); break;
      case Want::Numbers:
        if (!v.is_array() || (r.n && v.size() != r.n) || !std::all_of(v.begin(), v.end(), [](const nlohmann::json& e) { return e.is_number(); }))
          refuse(r.n ? "an array of " + std::to_string(r.n) + " numbers" : std::string("an array of numbers"));
        break;
      case Want::Indices:
        if (!v.is_array() || !std::all_of(v.begin(), v.end(), [](const nlohmann::json& e) { return gltf_integer(e, 0); }))
          refuse("an array of integers >= 0");
        break;
      case Want::IndexMap:
        if (!v.is_object() || !std::all_of(v.begin(), v.end(), [](const nlohmann::json& e) { return gltf_integer(e, 0); }))
          refuse("an object of accessor indices (integers >= 0)");
        break;
      case Want::Object:
        if (!v.is_object()) refuse("an object");
        check_gltf_object(path, at, v, r.object);
        break;
      case Want::Objects:
        if (!v.is_array()) refuse("an array of objects");
        for (size_t i = 0; i < v.size(); ++i) {
          const std::string item = who + " " + r.object + " " + std::to_string(i);
          if (!v[i].is_object()) throw Error(path + ": " + item + ": found " + v[i].dump().substr(0, 40) + ", expected an object");
          check_gltf_object(path, item, v[i], r.object);
        }
        break;
    }
  }
}

void check_gltf_types(const std::string& path, const nlohmann::json& doc) {
  static const std::vector<std::pair<const char*, const char*>> lists = {
      {"accessors", "accessor"}, {"bufferViews", "bufferView"}, {"buffers", "buffer"}, {"nodes", "node"},
      {"meshes", "mesh"}, {"materials", "material"}, {"textures", "texture"}, {"images", "image"},
      {"samplers", "sampler"}, {"cameras", "camera"}, {"scenes", "scene"}};
  for (const auto& [list, kind] : lists) {
    const auto it = doc.find(list);
    if (it == doc.end()) continue;
    if (!it->is_array()) throw Error(path + ": " + list + ": found " + it->dump().substr(0, 40) + ", expected an array of objects");
    for (size_t i = 0; i < it->size(); ++i) {
      const nlohmann::json& o = (*it)[i];
      const std::string name = o.is_object() && o.contains("name") && o["name"].is_string() ? o["name"].get<std::string>() : "";
      const std::string who = label(kind, i, name);
      if (!o.is_object()) throw Error(path + ": " + who + ": found " + o.dump().substr(0, 40) + ", expected an object");
      check_gltf_object(path, who, o, kind);
      // glTF 2.0's required properties of a camera, named with it (tinygltf said "'znear' property is missing in
      // PerspectiveCamera.", naming no camera; an auditor's find)
      if (std::strcmp(kind, "camera") == 0) {
        static const std::vector<std::pair<std::string, std::vector<std::string>>> required = {
            {"perspective", {"yfov", "znear"}}, {"orthographic", {"xmag", "ymag", "zfar", "znear"}}};
        if (!o.contains("type"))
          throw Error(path + ": " + who + ": has no type; expected \"perspective\" or \"orthographic\" (glTF 2.0 requires it)");
        for (const auto& [projection, keys] : required)
          if (o.contains(projection))
            for (const std::string& key : keys)
              if (!o[projection].contains(key)) {
                std::string all;  // "yfov and znear", "xmag, ymag, zfar and znear"
                for (size_t k = 0; k < keys.size(); ++k)
                  all.append(k == 0 ? "" : k + 1 == keys.size() ? " and " : ", ").append(keys[k]);
                throw Error(path + ": " + who + ": its " + projection + " has no " + key + "; glTF 2.0 requires it (" + projection +
                            ": " + all + ")");
              }
      }
      // glTF 2.0: a node's transform is a matrix or TRS, not both (the translation beside a matrix was dropped)
      if (std::strcmp(kind, "node") == 0 && o.contains("matrix"))
        for (const char* trs : {"translation", "rotation", "scale"})
          if (o.contains(trs))
            throw Error(path + ": " + who + ": has both matrix and " + trs + "; expected one or the other (glTF 2.0: a "
                        "node's transform is a matrix, or any of translation, rotation and scale)");
    }
  }
  // KHR_lights_punctual's lights: tinygltf reads an absent range as 0, so a range of 0 (which glTF refuses:
  // it must be > 0) is told apart here.
  if (const auto ext = doc.find("extensions"); ext != doc.end() && ext->is_object())
    if (const auto kl = ext->find("KHR_lights_punctual"); kl != ext->end() && kl->is_object())
      if (const auto lights = kl->find("lights"); lights != kl->end() && lights->is_array())
        for (size_t i = 0; i < lights->size(); ++i) {
          const nlohmann::json& o = (*lights)[i];
          const std::string name = o.is_object() && o.contains("name") && o["name"].is_string() ? o["name"].get<std::string>() : "";
          const std::string who = label("light", i, name);
          if (!o.is_object()) throw Error(path + ": " + who + ": found " + o.dump().substr(0, 40) + ", expected an object");
          check_gltf_object(path, who, o, "light");
          if (const auto r = o.find("range"); r != o.end() && !(r->get<double>() > 0.0))
            throw Error(path + ": " + who + ": range: found " + r->dump() +
                        ", expected a number > 0 (metres; leave it out for a light without a range)");
        }
  // (tinygltf read a string, or an array of non-strings, as no extensions: a required one went unnoticed)
  for (const char* key : {"extensionsUsed", "extensionsRequired"})
    if (const auto it = doc.find(key);
        it != doc.end() && (!it->is_array() || !std::all_of(it->begin(), it->end(), [](const nlohmann::json& e) { return e.is_string(); })))
      throw Error(path + ": " + key + ": found " + it->dump().substr(0, 40) + ", expected an array of extension names (strings)");
  if (const auto it = doc.find("scene"); it != doc.end() && !gltf_integer(*it, 0))
    throw Error(path + ": scene: found " + it->dump().substr(0, 40) + ", expected the index of a scene (an integer >= 0)");
}

// What tinygltf would otherwise meet unprepared, checked on the file's JSON first: extensions it cannot
// decode (Draco and meshopt compression leave accessors without data, which tinygltf reports as a broken
// bufferView), and external buffers and images that are missing, not regular files or too large.
// `binary`: the file is a .glb, whose BIN chunk holds `bin_bytes` bytes (-1: it has none).
void check_before_tinygltf(const std::string& path, const nlohmann::json& doc, bool binary, int64_t bin_bytes) {
  if (!doc.is_object()) throw Error(path + ": expected a JSON object at the top of the glTF file");
  // glTF 2.0 requires asset (with its version); tinygltf's message was '"asset" object not found in .gltf or not
  // an object type' (a .glb too).
  if (const auto it = doc.find("asset"); it == doc.end() || !it->is_object())
    throw Error(path + ": " + (it == doc.end() ? std::string("has no asset") : "asset: found " + it->dump().substr(0, 40)) +
                "; expected the object every glTF file has, with its version: \"asset\": {\"version\": \"2.0\"}");
  // (tinygltf said the same of an asset without a version string: that asset was not found)
  if (const auto v = doc["asset"].find("version"); v == doc["asset"].end() || !v->is_string())
    throw Error(path + ": asset.version: " + (v == doc["asset"].end() ? std::string("missing") : "found " + v->dump().substr(0, 40)) +
                "; expected the glTF version as a string: \"asset\": {\"version\": \"2.0\"}");
  check_gltf_types(path, doc);
  // An accessor's type: tinygltf's message was 'Unsupported `type` for accessor object. Got "VEC7"', unnamed.
  if (const auto it = doc.find("accessors"); it != doc.end())
    for (size_t i = 0; i < it->size(); ++i) {
      const nlohmann::json& o = (*it)[i];
      static const std::set<std::string> types = {"SCALAR", "VEC2", "VEC3", "VEC4", "MAT2", "MAT3", "MAT4"};
      if (const auto t = o.find("type"); t != o.end() && t->is_string() && !types.count(t->get<std::string>()))
        throw Error(path + ": " + label("accessor", i, o.value("name", std::string())) + ": type " + quoted(t->get<std::string>()) +
                    " is no glTF 2.0 accessor type; expected SCALAR, VEC2, VEC3, VEC4, MAT2, MAT3 or MAT4");
    }
  if (const auto it = doc.find("extensionsRequired"); it != doc.end() && it->is_array())
    for (const nlohmann::json& e : *it)
      if (e.is_string() && !kSupportedExtensions.count(e.get<std::string>())) {
        const std::string name = e.get<std::string>();
        std::string hint;
        if (name == "KHR_draco_mesh_compression" || name == "EXT_meshopt_compression" || name == "KHR_meshopt_compression")
          hint = " (compressed meshes: export the file without mesh compression)";
        else if (name == "KHR_texture_basisu" || name == "EXT_texture_webp")
          hint = " (export the textures as PNG or JPEG)";
        throw Error(path + ": extension " + quoted(name) + " is listed in extensionsRequired but spadgen does not support it" + hint);
      }
  // References tinygltf checks with messages of its own ("primitive indices accessor out of bounds", 'image[0]
  // bufferView "7" not found in the scene.'), and an accessor's componentType ("Invalid `componentType` in
  // accessor. Got 1234"): named here, with what was expected, in read_accessor's and check_view_range's words.
  const auto count_of = [&](const char* list) {
    const auto l = doc.find(list);
    return l != doc.end() && l->is_array() ? l->size() : size_t{0};
  };
  const auto reference = [&](const std::string& who, const nlohmann::json& o, const char* key, const char* list, const char* one) {
    const auto r = o.find(key);
    if (r == o.end() || !r->is_number_integer()) return;
    const size_t n = count_of(list);
    if (r->get<int64_t>() < 0 || static_cast<uint64_t>(r->get<int64_t>()) >= n)
      throw Error(path + ": " + who + (std::string(key) != one ? std::string(" ") + key : std::string()) + ": " + one + " " +
                  r->dump() + " does not exist (the file has " + std::to_string(n) + " " + list + ")");
  };
  const auto each = [&](const char* list, const char* one, const auto& check) {
    if (const auto l = doc.find(list); l != doc.end() && l->is_array())
      for (size_t i = 0; i < l->size(); ++i)
        if ((*l)[i].is_object()) check(label(one, i, (*l)[i].value("name", std::string())), (*l)[i]);
  };
  each("accessors", "accessor", [&](const std::string& who, const nlohmann::json& a) {
    reference(who, a, "bufferView", "bufferViews", "bufferView");
    // (those tinygltf does not know: 5124 and 5127-5130 are named later, as the attribute or indices that has them)
    if (const auto c = a.find("componentType"); c != a.end() && c->is_number_integer() && (c->get<int64_t>() < 5120 || c->get<int64_t>() > 5130))
      throw Error(path + ": " + who + ": componentType " + c->dump() + " is no glTF 2.0 component type; expected 5120 (BYTE), "
                  "5121 (UNSIGNED_BYTE), 5122 (SHORT), 5123 (UNSIGNED_SHORT), 5125 (UNSIGNED_INT) or 5126 (FLOAT)");
  });
  // Compressed data without the extension in extensionsRequired (it may be listed in extensionsUsed only,
  // with a fallback spadgen cannot tell from the compressed accessors): refused as well, naming the element.
  const auto compressed = [&](const std::string& who, const nlohmann::json& o, const char* extension) {
    if (const auto e = o.find("extensions"); e != o.end() && e->is_object() && e->contains(extension))
      throw Error(path + ": " + who + ": compressed with " + extension + ", which spadgen does not decode (export the file " +
                  "without mesh compression)");
  };
  each("bufferViews", "bufferView", [&](const std::string& who, const nlohmann::json& v) {
    compressed(who, v, "EXT_meshopt_compression");
    compressed(who, v, "KHR_meshopt_compression");
    reference(who, v, "buffer", "buffers", "buffer");
  });
  each("images", "image", [&](const std::string& who, const nlohmann::json& im) { reference(who, im, "bufferView", "bufferViews", "bufferView"); });
  each("meshes", "mesh", [&](const std::string& who, const nlohmann::json& m) {
    if (const auto prims = m.find("primitives"); prims != m.end() && prims->is_array())
      for (size_t j = 0; j < prims->size(); ++j)
        if ((*prims)[j].is_object()) {
          compressed(who + " primitive " + std::to_string(j), (*prims)[j], "KHR_draco_mesh_compression");
          reference(who + " primitive " + std::to_string(j), (*prims)[j], "indices", "accessors", "accessor");
          // Indices without a bufferView: glTF 2.0 reads them as zeros (every triangle degenerate), and tinygltf
          // refused the file with "accessor[1] invalid bufferView", naming no mesh (an auditor's find).
          if (const auto ix = (*prims)[j].find("indices"); ix != (*prims)[j].end() && ix->is_number_integer()) {
            const nlohmann::json& a = doc["accessors"][ix->get<size_t>()];
            if (a.is_object() && !a.contains("bufferView"))
              throw Error(path + ": " + who + " primitive " + std::to_string(j) + ": its indices are " +
                          label("accessor", ix->get<size_t>(), a.value("name", std::string())) +
                          ", which has no bufferView: glTF 2.0 reads it as zeros, so every triangle would be one point; "
                          "expected indices with a bufferView, or none (the vertices in order)");
          }
        }
  });
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  for (const char* kind : {"buffers", "images"}) {
    const auto list = doc.find(kind);
    if (list == doc.end() || !list->is_array()) continue;
    const bool buffer = std::strcmp(kind, "buffers") == 0;
    for (size_t i = 0; i < list->size(); ++i) {
      const nlohmann::json& b = (*list)[i];
      if (!b.is_object()) continue;
      const std::string name = b.contains("name") && b["name"].is_string() ? b["name"].get<std::string>() : "";
      const std::string who = label(buffer ? "buffer" : "image", i, name);
      // A buffer without a uri is a .glb's BIN chunk (glTF 2.0, 4.4.3.3): only the first buffer of a .glb can be
      // (tinygltf gave a second one the same bytes, and said "'uri' is missing" of a .gltf's naming no buffer).
      if (buffer && !b.contains("uri")) {
        if (!binary)
          throw Error(path + ": " + who + ": has no uri; expected the path of its file, relative to the glTF file, or a "
                      "data: URI (only the first buffer of a .glb may leave it out, for the .glb's BIN chunk)");
        if (i > 0)
          throw Error(path + ": " + who + ": has no uri, but only the first buffer of a .glb is its BIN chunk; expected "
                      "the path of its file or a data: URI");
        if (bin_bytes < 0)
          throw Error(path + ": " + who + ": has no uri, for the .glb's BIN chunk, but the file has no BIN chunk");
        if (b.contains("byteLength") && b["byteLength"].is_number() && b["byteLength"].get<double>() > double(bin_bytes))
          throw Error(path + ": " + who + ": byteLength is " + num_whole(b["byteLength"].get<double>()) + " but the .glb's BIN "
                      "chunk holds " + std::to_string(bin_bytes) + " bytes; expected at most its length");
        continue;
      }
      if (!b.contains("uri") || !b["uri"].is_string()) continue;
      const std::string uri = b["uri"].get<std::string>();
      // tinygltf reads exactly byteLength bytes of a buffer, and reported another length as a failure to
      // decode the data URI, or as "File size mismatch" naming no buffer.
      const auto check_length = [&](uintmax_t size, const std::string& what) {
        if (buffer && b.contains("byteLength") && b["byteLength"].is_number() && b["byteLength"].get<double>() != double(size))
          throw Error(path + ": " + who + ": byteLength is " + num_whole(b["byteLength"].get<double>()) + " but " + what +
                      " holds " + std::to_string(size) + " bytes; expected a byteLength equal to its size");
      };
      if (uri.rfind("data:", 0) == 0) {
        // glTF embeds bytes as base64 (3.6.1.1: data:<media type>;base64,<data>); anything else reached
        // tinygltf's "Failed to decode 'uri'", which named no buffer. (An image's data URI that does not
        // decode leaves its material with the factor, a warning of the loader, as a missing image file does.)
        if (!buffer) continue;
        const size_t comma = uri.find(',');
        if (comma == std::string::npos || !std::string_view(uri).substr(0, comma).ends_with(";base64"))
          throw Error(path + ": " + who + ": its data URI " + quoted(uri.substr(0, std::min<size_t>(uri.size(), 48)) + (uri.size() > 48 ? "..." : "")) +
                      " is not base64; expected data:<media type>;base64,<data> (glTF 2.0, 3.6.1.1)");
        // glTF names a buffer's two media types; tinygltf decodes those and a few of images and text, and
        // another (or none, as RFC 2397 allows) was its "File not found".
        static const std::set<std::string_view> kDecoded = {"application/octet-stream", "application/gltf-buffer", "text/plain",
                                                            "image/png", "image/jpeg", "image/bmp", "image/gif"};
        if (const std::string_view media = std::string_view(uri).substr(5, comma - 5 - 7); !kDecoded.count(media))
          throw Error(path + ": " + who + ": its data URI's media type is " + quoted(scenes::printable(std::string(media.substr(0, 48)))) +
                      "; expected data:application/octet-stream;base64, or data:application/gltf-buffer;base64, (glTF 2.0, "
                      "3.6.1.1: a buffer's data URI must name one of them)");
        size_t chars = uri.size() - comma - 1, pad = 0;
        while (pad < 2 && chars > 0 && uri[comma + chars - pad] == '=') ++pad;
        for (size_t k = comma + 1; k < uri.size() - pad; ++k) {
          const auto ch = static_cast<unsigned char>(uri[k]);
          if (!std::isalnum(ch) && ch != '+' && ch != '/')
            throw Error(path + ": " + who + ": its data URI's base64 has " +
                        (std::isprint(ch) ? "'" + std::string(1, char(ch)) + "'" : "byte " + std::to_string(ch)) + " at character " +
                        std::to_string(k - comma - 1) + " of " + std::to_string(chars) + "; expected A-Z, a-z, 0-9, + and /, then up to two =" +
                        (ch == '-' || ch == '_' ? " (base64, not its URL-safe variant)" : std::isspace(ch) ? " (no line breaks or spaces)" : ""));
        }
        // without its = padding (2 or 3 characters in the last group) it decodes, as tinygltf reads it; 1 cannot
        if (pad == 0 && chars % 4 == 1)
          throw Error(path + ": " + who + ": its data URI's base64 has " + std::to_string(chars) +
                      " characters, one more than a multiple of 4, which no data encodes (the data cut short)");
        if (pad > 0 && chars % 4 != 0)
          throw Error(path + ": " + who + ": its data URI's base64 has " + std::to_string(chars) +
                      " characters with its = padding; expected a multiple of 4 (the data cut short)");
        check_length(chars / 4 * 3 - pad + (chars % 4 == 0 ? 0 : chars % 4 - 1), "its data URI");
        continue;
      }
      if (uri.empty())
        throw Error(path + ": " + who + ": its uri is empty; expected the path of its file, relative to the glTF file, or a "
                    "data: URI" + (buffer && binary && i == 0 ? " (or no uri, for the .glb's BIN chunk)" : ""));
      // A NUL byte ends a path for the system: the file opened would be another than the one named.
      if (uri.find('\0') != std::string::npos || uri_decode(uri).find('\0') != std::string::npos)
        throw Error(path + ": " + who + ": its uri " + quoted(scenes::printable(uri)) + " holds a NUL byte" +
                    (uri.find('\0') == std::string::npos ? " (%00)" : "") + "; expected a path without one");
      if (std::filesystem::path(uri_decode(uri)).is_absolute() || uri.find("://") != std::string::npos)
        throw Error(path + ": " + who + ": its uri " + quoted(uri) +
                    " is absolute; expected a path relative to the glTF file's folder, or a data: URI");
      std::string file = (dir / uri_decode(uri)).string();
      std::string problem = file_problem(file, buffer ? kMaxGltfFileBytes : kMaxImageFileBytes);
      if (problem == "does not exist" && uri_decode(uri) != uri) {
        file = (dir / uri).string();
        problem = file_problem(file, buffer ? kMaxGltfFileBytes : kMaxImageFileBytes);
      }
      if (problem == "does not exist") {
        // A missing image leaves its material with the factor (a warning, from the loader); a missing
        // buffer leaves nothing to load.
        if (buffer)
          throw Error(path + ": " + who + ": its file " + quoted(uri) + " was not found in " +
                      (dir.empty() ? std::string(".") : dir.string()));
      } else if (!problem.empty()) {
        throw Error(path + ": " + who + ": its file " + quoted(uri) + " " + problem);
      } else if (buffer) {
        std::error_code ec;
        const uintmax_t size = std::filesystem::file_size(file, ec);
        if (!ec) check_length(size, "its file " + quoted(uri));
      }
    }
  }
}

// tinygltf reads buffer and image files whole: through this reader, never more than the stated limit.
bool read_whole_file_bounded(std::vector<unsigned char>* out, std::string* err, const std::string& file, void*) {
  try {
    const std::string bytes = read_file_bounded(file, kMaxGltfFileBytes, "file");
    out->assign(bytes.begin(), bytes.end());
    return true;
  } catch (const Error& e) {
    if (err) *err = e.what();
    return false;
  }
}

}  // namespace

Scene load_gltf(const std::string& path, const std::string& scene_name, const SceneEdits& edits) {
  const std::string problem = file_problem(path, kMaxGltfFileBytes);
  if (problem == "does not exist") throw Error(path + ": glTF file not found");
  if (!problem.empty()) throw Error(path + ": the glTF file " + problem);
  // Its first bytes first: a file that is neither JSON nor a .glb is refused before it is read whole (a 1 GB
  // file of zeros took 2.1 GB and 13-25 s to be refused as "unexpected end of input").
  {
    std::ifstream in(path, std::ios::binary);
    std::string head(4096, '\0');
    in.read(head.data(), static_cast<std::streamsize>(head.size()));
    head.resize(static_cast<size_t>(std::max<std::streamsize>(0, in.gcount())));
    const size_t from = head.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
    bool binary = false;
    if (head.compare(0, 4, "glTF") != 0 && head.find_first_not_of(" \t\r\n", from) != std::string::npos)
      (void)gltf_json(path, head, &binary);  // throws, naming what the file begins with, unless it begins as JSON
  }
  return parse_gltf(read_file_bounded(path, kMaxGltfFileBytes, "glTF file"), path, scene_name, edits);
}

std::vector<std::string> gltf_external_files(const std::string& path) {
  const std::string bytes = read_file_bounded(path, kMaxGltfFileBytes, "glTF file");
  bool binary = false;
  const nlohmann::json doc = parse_json(gltf_json(path, bytes, &binary), binary ? path + " (its JSON chunk)" : path,
                                        {/*comments=*/false, /*reject_duplicates=*/false});
  const std::filesystem::path dir = std::filesystem::path(path).parent_path();
  std::vector<std::string> files;
  for (const char* kind : {"buffers", "images"}) {
    const auto list = doc.find(kind);
    if (list == doc.end() || !list->is_array()) continue;
    for (const nlohmann::json& b : *list) {
      if (!b.is_object() || !b.contains("uri") || !b["uri"].is_string()) continue;
      const std::string uri = b["uri"].get<std::string>();
      if (uri.rfind("data:", 0) == 0) continue;
      const std::string decoded = (dir / uri_decode(uri)).string(), raw = (dir / uri).string();
      files.push_back(file_problem(decoded, kMaxGltfFileBytes) == "does not exist" && file_problem(raw, kMaxGltfFileBytes) != "does not exist"
                          ? raw : decoded);
    }
  }
  return files;
}

Scene parse_gltf(const std::string& bytes, const std::string& path, const std::string& scene_name, const SceneEdits& edits) {
  if (bytes.size() > kMaxGltfFileBytes)
    throw Error(path + ": the glTF file is " + size_text(bytes.size()) + ", larger than the " + size_text(kMaxGltfFileBytes) +
                " spadgen reads");
  // .glb and .gltf are told apart by content: exporters and users both mislabel them.
  bool binary = false;
  int64_t bin_bytes = -1;
  std::string unknown_chunk;
  const std::string json_text = gltf_json(path, bytes, &binary, &bin_bytes, &unknown_chunk);
  // Parsed here first, without recursion and to a bounded depth: tinygltf turns extras into its own
  // values recursively, and a file nested 15,000 deep would exhaust the stack there.
  // A key twice in one object: glTF 2.0 (JSON encoding) asks writers for unique keys and readers to take the
  // later value, as tinygltf does; said, since a file that has one was likely edited by hand or merged.
  std::string duplicate;
  check_before_tinygltf(path, parse_json(json_text, binary ? path + " (its JSON chunk)" : path,
                                         {/*comments=*/false, /*reject_duplicates=*/false, &duplicate}),
                        binary, bin_bytes);

  tinygltf::Model model;
  tinygltf::TinyGLTF io;
  io.SetImageLoader(load_image_checked, &model);
  io.SetFsCallbacks({&tinygltf::FileExists, &tinygltf::ExpandFilePath, &read_whole_file_bounded,
                     &tinygltf::WriteWholeFile, nullptr});
  std::string err, warn;
  const std::string base_dir = std::filesystem::path(path).parent_path().string();
  bool ok = false;
  // tinygltf 2.7 refuses a second chunk that is not BIN: it sees the file up to the JSON chunk's end.
  std::string glb_without_unknown;
  if (!unknown_chunk.empty()) {
    glb_without_unknown = bytes.substr(0, 20 + json_text.size());
    const auto length = static_cast<uint32_t>(glb_without_unknown.size());
    std::memcpy(glb_without_unknown.data() + 8, &length, 4);
  }
  const std::string& glb = unknown_chunk.empty() ? bytes : glb_without_unknown;
  try {
    ok = binary ? io.LoadBinaryFromMemory(&model, &err, &warn, reinterpret_cast<const unsigned char*>(glb.data()),
                                          static_cast<unsigned int>(glb.size()), base_dir)
                : io.LoadASCIIFromString(&model, &err, &warn, bytes.data(), static_cast<unsigned int>(bytes.size()), base_dir);
  } catch (const std::bad_alloc&) {
    throw;  // (memory, not the file: "malformed glTF (tinygltf: std::bad_alloc)" of a valid 16384^2 texture)
  } catch (const std::exception& e) {
    // tinygltf 2.7 throws std::out_of_range on some malformed files (a GLB buffer of byteLength 0).
    throw Error(path + ": malformed glTF (tinygltf: " + e.what() + ")");
  }
  // tinygltf ends each of its messages with a newline; one line reads better in a terminal and a log.
  while (!err.empty() && (err.back() == '\n' || err.back() == ' ')) err.pop_back();
  for (size_t pos; (pos = err.find('\n')) != std::string::npos;) err.replace(pos, 1, "; ");
  // tinygltf quotes a data: URI it could not decode whole: a 200 kB buffer made a 266 kB line.
  for (size_t pos = 0; (pos = err.find("data:", pos)) != std::string::npos;) {
    size_t end = pos;
    while (end < err.size() && err[end] != ' ' && err[end] != '\'' && err[end] != '"') ++end;
    constexpr size_t kShown = 48;
    if (end - pos > kShown + 16) {
      const std::string tail = "... (" + std::to_string(end - pos) + " characters)";
      err.replace(pos + kShown, end - pos - kShown, tail);
      end = pos + kShown + tail.size();
    }
    pos = end;
  }
  if (!ok) throw Error(path + ": " + (err.empty() ? std::string("tinygltf could not load the file") : err));
  // glTF 1.0 and a future 3.0 are other formats: read as 2.0, a file of theirs would be misread.
  if (model.asset.version.rfind("2.", 0) != 0)
    throw Error(path + ": asset.version is '" + scenes::printable(model.asset.version) +
                "'; expected a glTF 2.x file (asset.version \"2.0\")");

  // minVersion: the least glTF version a reader needs (a 2.1 file may use what 2.0 readers misread).
  if (!model.asset.minVersion.empty() && model.asset.minVersion != "2.0")
    throw Error(path + ": asset.minVersion is '" + scenes::printable(model.asset.minVersion) +
                "': the file needs a reader of that glTF version, and spadgen reads glTF 2.0");

  Scene scene;
  scene.source = path;
  if (!unknown_chunk.empty())
    scene.warnings.push_back("the .glb's second chunk is of type " + unknown_chunk + ", not BIN: ignored, with any "
                             "chunk after it (glTF 2.0: readers ignore chunks of unknown types; the file has no BIN chunk)");
  if (!duplicate.empty())
    scene.warnings.push_back(duplicate + " (the first such key; glTF 2.0 asks for unique keys, and the later value is "
                             "taken, the earlier ignored)");
  // An image file that could not be read is two lines of tinygltf's ("File not found : a.png", then "Failed to
  // load external 'uri' for image[0] name = []"): said once, as the image's, where a texture uses it (the two
  // raw lines came before the texture's own warning).
  std::map<int, std::string> image_files;
  std::string file_problem;  // the line before, when it was a file's
  std::istringstream lines(warn + "\n" + err);
  static constexpr std::string_view kImage = "Failed to load external 'uri' for image[", kNotFound = "File not found : ",
                                     kEmpty = "File is empty : ", kReadError = "File read error : ";
  for (std::string line; std::getline(lines, line);) {
    if (line.starts_with(kImage) && !file_problem.empty()) {
      const int image = std::atoi(line.c_str() + kImage.size());
      image_files[image] = file_problem.starts_with(kNotFound)
                               ? "its file " + file_problem.substr(kNotFound.size()) + " was not found (beside " + path + ")"
                           : file_problem.starts_with(kEmpty) ? "its file " + file_problem.substr(kEmpty.size()) + " is empty"
                                                              : "its file could not be read (" + file_problem + ")";
      file_problem.clear();
      continue;
    }
    if (!file_problem.empty()) scene.warnings.push_back("tinygltf: " + file_problem);
    file_problem.clear();
    if (line.starts_with(kNotFound) || line.starts_with(kReadError) || line.starts_with(kEmpty))
      file_problem = line;
    else if (!line.empty() && line.find("'inverseBindMatrices' property is missing") == std::string::npos)
      // inverseBindMatrices is optional (glTF 2.0: identity matrices without it), and skins are read as such
      scene.warnings.push_back("tinygltf: " + line);
  }
  if (!file_problem.empty()) scene.warnings.push_back("tinygltf: " + file_problem);
  Loader(path, model, edits, scene, std::move(image_files)).load(scene_name);
  return scene;
}

Objects objects_of(const Scene& scene) {
  Objects o;
  o.mesh_object.assign(scene.meshes.size(), -1);
  const auto node_of = [&](const Mesh& m) { return m.gltf_node >= 0 && size_t(m.gltf_node) < scene.nodes.size() ? m.gltf_node : -1; };
  std::vector<char> has_mesh(scene.nodes.size(), 0);
  for (const Mesh& m : scene.meshes)
    if (node_of(m) >= 0) has_mesh[size_t(m.gltf_node)] = 1;
  std::vector<int> node_object(scene.nodes.size(), -1);
  for (size_t n = 0; n < scene.nodes.size(); ++n)
    if (has_mesh[n]) {
      node_object[n] = int(o.list.size());
      o.list.push_back({int(o.list.size()), scene.nodes[n].name, int(n), {}});
    }
  for (size_t m = 0; m < scene.meshes.size(); ++m) {
    const int node = node_of(scene.meshes[m]);
    int id = node >= 0 ? node_object[size_t(node)] : int(o.list.size());
    if (node < 0) o.list.push_back({id, "", -1, {}});
    o.mesh_object[m] = id;
    o.list[size_t(id)].meshes.push_back(int(m));
  }
  return o;
}

std::string summarize(const Scene& scene) {
  std::ostringstream s;
  s << "glTF: " << scene.source << "\n";
  // Every node by name: the scene file's nodes section refers to them so.
  s << "nodes: " << scene.nodes.size() << "\n";
  for (size_t i = 0; i < scene.nodes.size(); ++i) {
    const Node& n = scene.nodes[i];
    s << "  " << i << " " << (n.name.empty() ? std::string("(no name)") : "'" + n.name + "'");
    if (n.parent >= 0) s << " in " << n.parent;
    if (n.loaded) {
      const glm::dvec3 p(n.world[3]);
      s << ", at (" << p.x << ", " << p.y << ", " << p.z << ")";
    } else {
      s << ", not in the loaded scene";
    }
    s << "\n";
  }
  // The ground truth's objects: their ids are what ground_truth.exr's object<j>.id and evaluate report.
  const Objects objects = objects_of(scene);
  s << "objects (ground-truth ids): " << objects.list.size() << "\n";
  for (const Object& o : objects.list)
    s << "  " << o.id << " "
      << (!o.name.empty() ? "'" + o.name + "'" : o.node >= 0 ? "node " + std::to_string(o.node) + " (unnamed)" : std::string("(mesh without node)"))
      << ", "
      << o.meshes.size() << (o.meshes.size() == 1 ? " mesh" : " meshes") << "\n";
  s << "meshes: " << scene.meshes.size() << " (" << scene.triangle_count() << " triangles)\n";
  for (const Mesh& m : scene.meshes)
    s << "  " << m.name << ": " << m.triangle_count() << " triangles, material "
      << (m.material >= 0 && static_cast<size_t>(m.material) < scene.materials.size()
              ? "'" + scene.materials[static_cast<size_t>(m.material)].name + "'"
              : std::string("(default)"))
      << "\n";
  s << "materials: " << scene.materials.size() << "\n";
  for (size_t i = 0; i < scene.materials.size(); ++i) {
    const Material& m = scene.materials[i];
    s << "  " << i << " '" << m.name << "': base colour (" << m.base_color.r << ", " << m.base_color.g << ", "
      << m.base_color.b << "), metallic " << m.metallic << ", roughness " << m.roughness;
    if (m.base_color_texture >= 0)
      s << ", baseColorTexture '" << scene.textures[static_cast<size_t>(m.base_color_texture)].name << "' ("
        << scene.textures[static_cast<size_t>(m.base_color_texture)].width << "x"
        << scene.textures[static_cast<size_t>(m.base_color_texture)].height << ", TEXCOORD_" << m.base_color_texcoord
        << (m.base_color_transformed ? " through KHR_texture_transform" : "") << ")";
    if (m.double_sided) s << ", double-sided";
    std::vector<std::string> ext;
    if (m.emissive != glm::vec3(0.0f))
      ext.push_back("emissive (" + num(m.emissive.r) + ", " + num(m.emissive.g) + ", " +
                    num(m.emissive.b) + ")");
    if (m.transmission > 0) ext.push_back("KHR_materials_transmission " + num(m.transmission));
    if (m.ior != 1.5f || m.transmission > 0) ext.push_back("KHR_materials_ior " + num(m.ior));
    if (m.thickness_m > 0 || std::isfinite(m.attenuation_distance_m))
      ext.push_back("KHR_materials_volume thickness " + num(m.thickness_m) + " m, attenuation distance " +
                    (std::isfinite(m.attenuation_distance_m) ? num(m.attenuation_distance_m) + " m"
                                                             : std::string("inf")));
    for (const std::string& e : ext) s << "; " << e;
    s << "\n";
  }
  s << "cameras: " << scene.cameras.size() << "\n";
  for (const Camera& c : scene.cameras) {
    const glm::dvec3 p(c.world_from_camera[3]);
    s << "  '" << c.name << "': yfov " << c.yfov_rad * 180.0 / kPi << " deg";
    if (c.aspect_ratio > 0) s << ", aspect ratio " << c.aspect_ratio;
    s << ", at (" << p.x << ", " << p.y << ", " << p.z << ")\n";
  }
  s << "lights: " << scene.lights.size() << "\n";
  for (const Light& l : scene.lights) {
    const char* type = l.type == Light::Type::Point ? "point" : l.type == Light::Type::Spot ? "spot" : "directional";
    s << "  '" << l.name << "': " << type << ", intensity " << l.intensity
      << (l.type == Light::Type::Directional ? " lx" : " cd");
    if (l.type == Light::Type::Spot)
      s << ", cone " << l.inner_cone_rad * 180.0 / kPi << " to " << l.outer_cone_rad * 180.0 / kPi << " deg";
    s << "\n";
  }
  s << "warnings: " << scene.warnings.size() << "\n";
  for (const std::string& w : scene.warnings) s << "  " << w << "\n";
  return s.str();
}

}  // namespace spadgen::scenes
