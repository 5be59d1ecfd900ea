// A small writer-side helper over tinygltf::Model: packs meshes and images into one buffer with the
// alignment and accessor bounds the glTF specification requires, then writes and re-reads the file.
#pragma once
#include <tiny_gltf.h>

#include <glm/glm.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace spadgen::scenes_gen {

struct MeshData {
  std::vector<glm::vec3> positions;
  std::vector<glm::vec3> normals;     // empty or one per position
  std::vector<glm::vec2> texcoords;   // empty or one per position (TEXCOORD_0)
  std::vector<uint32_t> indices;      // 3 per triangle, counter-clockwise seen from outside
};

class GltfBuilder {
 public:
  explicit GltfBuilder(const std::string& copyright_note);

  int add_material(const tinygltf::Material& material);
  int add_mesh(const std::string& name, const MeshData& data, int material);
  int add_png_texture(const std::string& name, const std::vector<unsigned char>& png, int wrap_s,
                      int wrap_t);
  int add_perspective_camera(const std::string& name, double yfov_rad, double aspect_ratio);
  // Adds a node under `parent` (-1: a root of the scene).
  int add_node(const tinygltf::Node& node, int parent = -1);
  void use_extension(const std::string& name);

  // Writes `path` (.gltf). With bin_name "" the buffer is embedded as base64, else written beside
  // the file under that name. The file is then loaded back so that a scene tinygltf cannot read
  // never leaves the generator.
  void write(const std::string& path, const std::string& scene_name, const std::string& bin_name);

  tinygltf::Model& model() { return model_; }

 private:
  int add_view(const void* data, size_t bytes, int target);
  int add_accessor(int view, int component_type, int type, size_t count);

  tinygltf::Model model_;
  std::vector<int> roots_;
};

// A material value for KHR extensions: {"key": number, ...}.
tinygltf::Value object(std::initializer_list<std::pair<const char*, tinygltf::Value>> members);

}  // namespace spadgen::scenes_gen
