#include "gltf_builder.h"

#include <algorithm>
#include <cstring>
#include <limits>
#include <stdexcept>

namespace spadgen::scenes_gen {

tinygltf::Value object(std::initializer_list<std::pair<const char*, tinygltf::Value>> members) {
  tinygltf::Value::Object o;
  for (const auto& [key, value] : members) o[key] = value;
  return tinygltf::Value(o);
}

GltfBuilder::GltfBuilder(const std::string& copyright_note) {
  model_.asset.version = "2.0";
  model_.asset.generator = "spadgen scenes_gen";
  model_.asset.copyright = copyright_note;
  model_.buffers.emplace_back();
}

int GltfBuilder::add_view(const void* data, size_t bytes, int target) {
  std::vector<unsigned char>& buf = model_.buffers[0].data;
  // Every view starts on a 4-byte boundary: accessor offsets must be multiples of the component size.
  while (buf.size() % 4 != 0) buf.push_back(0);
  tinygltf::BufferView view;
  view.buffer = 0;
  view.byteOffset = buf.size();
  view.byteLength = bytes;
  view.target = target;
  const auto* p = static_cast<const unsigned char*>(data);
  buf.insert(buf.end(), p, p + bytes);
  model_.bufferViews.push_back(view);
  return static_cast<int>(model_.bufferViews.size()) - 1;
}

int GltfBuilder::add_accessor(int view, int component_type, int type, size_t count) {
  tinygltf::Accessor a;
  a.bufferView = view;
  a.componentType = component_type;
  a.type = type;
  a.count = count;
  model_.accessors.push_back(a);
  return static_cast<int>(model_.accessors.size()) - 1;
}

int GltfBuilder::add_material(const tinygltf::Material& material) {
  model_.materials.push_back(material);
  for (const auto& ext : material.extensions) use_extension(ext.first);
  return static_cast<int>(model_.materials.size()) - 1;
}

int GltfBuilder::add_mesh(const std::string& name, const MeshData& data, int material) {
  const size_t n = data.positions.size();
  if (n == 0 || data.indices.empty() || data.indices.size() % 3 != 0)
    throw std::runtime_error("mesh '" + name + "': no triangles");
  if ((!data.normals.empty() && data.normals.size() != n) ||
      (!data.texcoords.empty() && data.texcoords.size() != n))
    throw std::runtime_error("mesh '" + name + "': attribute counts differ");
  if (*std::max_element(data.indices.begin(), data.indices.end()) >= n)
    throw std::runtime_error("mesh '" + name + "': index out of range");

  tinygltf::Primitive prim;
  prim.mode = TINYGLTF_MODE_TRIANGLES;
  prim.material = material;

  const int pos = add_accessor(add_view(data.positions.data(), n * sizeof(glm::vec3), TINYGLTF_TARGET_ARRAY_BUFFER),
                               TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n);
  // POSITION min and max are required by the specification (viewers use them for bounds).
  glm::vec3 lo(std::numeric_limits<float>::max()), hi(-std::numeric_limits<float>::max());
  for (const glm::vec3& p : data.positions) {
    lo = glm::min(lo, p);
    hi = glm::max(hi, p);
  }
  model_.accessors[pos].minValues = {lo.x, lo.y, lo.z};
  model_.accessors[pos].maxValues = {hi.x, hi.y, hi.z};
  prim.attributes["POSITION"] = pos;
  if (!data.normals.empty())
    prim.attributes["NORMAL"] =
        add_accessor(add_view(data.normals.data(), n * sizeof(glm::vec3), TINYGLTF_TARGET_ARRAY_BUFFER),
                     TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC3, n);
  if (!data.texcoords.empty())
    prim.attributes["TEXCOORD_0"] =
        add_accessor(add_view(data.texcoords.data(), n * sizeof(glm::vec2), TINYGLTF_TARGET_ARRAY_BUFFER),
                     TINYGLTF_COMPONENT_TYPE_FLOAT, TINYGLTF_TYPE_VEC2, n);

  // The smallest index type that holds every index keeps the shipped files small.
  if (n <= std::numeric_limits<uint16_t>::max()) {
    std::vector<uint16_t> idx(data.indices.begin(), data.indices.end());
    prim.indices = add_accessor(add_view(idx.data(), idx.size() * sizeof(uint16_t), TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                                TINYGLTF_COMPONENT_TYPE_UNSIGNED_SHORT, TINYGLTF_TYPE_SCALAR, idx.size());
  } else {
    prim.indices = add_accessor(add_view(data.indices.data(), data.indices.size() * sizeof(uint32_t),
                                         TINYGLTF_TARGET_ELEMENT_ARRAY_BUFFER),
                                TINYGLTF_COMPONENT_TYPE_UNSIGNED_INT, TINYGLTF_TYPE_SCALAR, data.indices.size());
  }

  tinygltf::Mesh mesh;
  mesh.name = name;
  mesh.primitives.push_back(prim);
  model_.meshes.push_back(mesh);
  return static_cast<int>(model_.meshes.size()) - 1;
}

int GltfBuilder::add_png_texture(const std::string& name, const std::vector<unsigned char>& png, int wrap_s,
                                 int wrap_t) {
  tinygltf::Image image;
  image.name = name;
  image.mimeType = "image/png";
  image.bufferView = add_view(png.data(), png.size(), 0);
  model_.images.push_back(image);

  tinygltf::Sampler sampler;
  sampler.magFilter = TINYGLTF_TEXTURE_FILTER_LINEAR;
  sampler.minFilter = TINYGLTF_TEXTURE_FILTER_LINEAR_MIPMAP_LINEAR;
  sampler.wrapS = wrap_s;
  sampler.wrapT = wrap_t;
  model_.samplers.push_back(sampler);

  tinygltf::Texture texture;
  texture.name = name;
  texture.source = static_cast<int>(model_.images.size()) - 1;
  texture.sampler = static_cast<int>(model_.samplers.size()) - 1;
  model_.textures.push_back(texture);
  return static_cast<int>(model_.textures.size()) - 1;
}

int GltfBuilder::add_perspective_camera(const std::string& name, double yfov_rad, double aspect_ratio) {
  tinygltf::Camera cam;
  cam.name = name;
  cam.type = "perspective";
  cam.perspective.yfov = yfov_rad;
  cam.perspective.aspectRatio = aspect_ratio;
  cam.perspective.znear = 0.01;
  // tinygltf writes zfar even when 0 (its "infinite" marker), which the specification forbids.
  cam.perspective.zfar = 100.0;
  model_.cameras.push_back(cam);
  return static_cast<int>(model_.cameras.size()) - 1;
}

int GltfBuilder::add_node(const tinygltf::Node& node, int parent) {
  model_.nodes.push_back(node);
  const int index = static_cast<int>(model_.nodes.size()) - 1;
  if (parent < 0)
    roots_.push_back(index);
  else
    model_.nodes.at(static_cast<size_t>(parent)).children.push_back(index);
  return index;
}

void GltfBuilder::use_extension(const std::string& name) {
  if (std::find(model_.extensionsUsed.begin(), model_.extensionsUsed.end(), name) == model_.extensionsUsed.end())
    model_.extensionsUsed.push_back(name);
}

void GltfBuilder::write(const std::string& path, const std::string& scene_name, const std::string& bin_name) {
  // An unnamed, empty scene is written in a form tinygltf cannot read back: always name it.
  tinygltf::Scene scene;
  scene.name = scene_name;
  scene.nodes = roots_;
  model_.scenes = {scene};
  model_.defaultScene = 0;
  model_.buffers[0].uri = bin_name;
  model_.buffers[0].name = bin_name.empty() ? scene_name : bin_name;

  tinygltf::TinyGLTF io;
  const bool embed_buffers = bin_name.empty();
  if (!io.WriteGltfSceneToFile(&model_, path, /*embedImages=*/true, embed_buffers, /*prettyPrint=*/true,
                               /*writeBinary=*/false))
    throw std::runtime_error("could not write " + path);

  tinygltf::Model back;
  std::string err, warn;
  if (!io.LoadASCIIFromFile(&back, &err, &warn, path))
    throw std::runtime_error("tinygltf cannot load back " + path + ": " + err);
  if (back.meshes.size() != model_.meshes.size() || back.nodes.size() != model_.nodes.size())
    throw std::runtime_error(path + " reads back different from what was written");
}

}  // namespace spadgen::scenes_gen
