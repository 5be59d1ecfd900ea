// The scene file's edits of glTF nodes and materials, as the loader applies them (load_gltf with
// SceneEdits): world positions against an independent computation of the edited transforms, the Euler
// convention, children, cameras and lights following their parent, matrix nodes, names, materials.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#define GLM_ENABLE_EXPERIMENTAL
#include <glm/gtc/matrix_transform.hpp>
#include <glm/gtc/quaternion.hpp>
#include <glm/gtx/euler_angles.hpp>

#include <cmath>
#include <string>
#include <vector>

#include "gltf_files.h"

namespace {

using namespace spadgen::test_gltf;
using spadgen::MaterialEdit;
using spadgen::NodeEdit;
using spadgen::SceneEdits;
using spadgen::scenes::Light;
using spadgen::scenes::Material;
using testing::HasSubstr;
using testing::Not;

constexpr double kDeg = kPi / 180.0;

SceneEdits node_edits(std::vector<NodeEdit> nodes) { return {std::move(nodes), {}}; }

NodeEdit node(const std::string& name) {
  NodeEdit e;
  e.name = name;
  return e;
}

std::string edit_error(const std::string& path, const SceneEdits& edits) {
  try {
    load_gltf(path, "", edits);
  } catch (const Error& e) {
    return e.what();
  }
  ADD_FAILURE() << "no spadgen::Error for " << path;
  return "";
}

// The rotations about each axis, from glm (not from the loader's own Euler code).
glm::dmat4 rx(double deg) { return glm::rotate(glm::dmat4(1.0), deg * kDeg, glm::dvec3(1, 0, 0)); }
glm::dmat4 ry(double deg) { return glm::rotate(glm::dmat4(1.0), deg * kDeg, glm::dvec3(0, 1, 0)); }
glm::dmat4 rz(double deg) { return glm::rotate(glm::dmat4(1.0), deg * kDeg, glm::dvec3(0, 0, 1)); }
glm::dvec3 apply(const glm::dmat4& m, const glm::dvec3& p) { return glm::dvec3(m * glm::dvec4(p, 1.0)); }

// The triangle of Gltf::triangle_mesh: (0,0,0), (1,0,0), (0,1,0), normals +Z.
const std::vector<glm::dvec3> kTriangle = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}};

void expect_positions(const spadgen::scenes::Mesh& m, const glm::dmat4& world, double tol = 1e-6) {
  ASSERT_EQ(m.positions.size(), kTriangle.size());
  for (size_t v = 0; v < kTriangle.size(); ++v) expect_vec(m.positions[v], apply(world, kTriangle[v]), tol);
}

// A translation component replaces the glTF's; the others stay, and every vertex moves by the difference.
TEST(SceneEdits, TranslationReplacesTheGltfsComponentAndMovesEveryVertexByTheDifference) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Plate"}, {"mesh", m}, {"translation", {1, 2, 3}}, {"rotation", {0, 0, std::sin(15 * kDeg), std::cos(15 * kDeg)}}});
  const std::string path = g.write(dir.path(), "t");
  const Scene before = load_gltf(path);
  NodeEdit e = node("Plate");
  e.translation_m[2] = 3.25;
  const Scene after = load_gltf(path, "", node_edits({e}));
  ASSERT_EQ(after.meshes.size(), 1u);
  for (size_t v = 0; v < 3; ++v)
    expect_vec(after.meshes[0].positions[v], glm::dvec3(before.meshes[0].positions[v]) + glm::dvec3(0, 0, 0.25), 1e-6);
  EXPECT_EQ(glm::dvec3(after.nodes[0].world[3]), glm::dvec3(1, 2, 3.25));
  // Normals do not change under a translation.
  EXPECT_EQ(after.meshes[0].normals, before.meshes[0].normals);
  e.translation_m = {-1.0, std::nullopt, std::nullopt};
  const Scene x = load_gltf(path, "", node_edits({e}));
  for (size_t v = 0; v < 3; ++v)
    expect_vec(x.meshes[0].positions[v], glm::dvec3(before.meshes[0].positions[v]) + glm::dvec3(-2, 0, 0), 1e-6);
}

// rotation_deg = [x, y, z] is R = Rz(z) Ry(y) Rx(x) on column vectors: about X first, then Y, then Z.
TEST(SceneEdits, RotationIsXyzEulerAnglesComposedAsRzRyRx) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Plate"}, {"mesh", m}, {"translation", {0, 0, -2}}});
  const std::string path = g.write(dir.path(), "r");
  NodeEdit e = node("Plate");
  // A plate tilted by 10 degrees about X: its normal +Z turns to (0, -sin 10, cos 10).
  e.rotation_rad = {10 * kDeg, 0.0, 0.0};
  Scene s = load_gltf(path, "", node_edits({e}));
  const glm::dvec3 n(0, -std::sin(10 * kDeg), std::cos(10 * kDeg));
  expect_vec(s.meshes[0].normals[0], n, 1e-7);
  expect_vec(glm::vec3(face_normal(s.meshes[0], 0)), n, 1e-6);
  expect_vec(s.meshes[0].positions[2], {0, std::cos(10 * kDeg), -2 + std::sin(10 * kDeg)});
  // The order: [90, 90, 0] takes (0, 1, 0) to (1, 0, 0) (Rx first: to +Z, then Ry: to +X); the other
  // order would leave it at +Z.
  e.rotation_rad = {90 * kDeg, 90 * kDeg, 0.0};
  s = load_gltf(path, "", node_edits({e}));
  expect_vec(s.meshes[0].positions[2], {1, 0, -2});
  // [0, 90, 90] takes (1, 0, 0) to (0, 0, -1) (Ry: to -Z, which Rz leaves); Ry after Rz would give +Y.
  e.rotation_rad = {0.0, 90 * kDeg, 90 * kDeg};
  s = load_gltf(path, "", node_edits({e}));
  expect_vec(s.meshes[0].positions[1], {0, 0, -3});
  // Any angles, against glm's rotations about each axis.
  e.rotation_rad = {-37 * kDeg, 21 * kDeg, 128 * kDeg};
  s = load_gltf(path, "", node_edits({e}));
  expect_positions(s.meshes[0], glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, -2)) * rz(128) * ry(21) * rx(-37));
}

// Angles not given are the glTF rotation's, in the same convention.
TEST(SceneEdits, AnglesNotGivenAreTheGltfRotations) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Plate"}, {"mesh", m}, {"rotation", {0, 0, std::sin(15 * kDeg), std::cos(15 * kDeg)}}});  // 30 deg about Z
  const std::string path = g.write(dir.path(), "p");
  NodeEdit e = node("Plate");
  e.rotation_rad[0] = 10 * kDeg;
  expect_positions(load_gltf(path, "", node_edits({e})).meshes[0], rz(30) * rx(10));
  e.rotation_rad = {std::nullopt, std::nullopt, 45 * kDeg};
  expect_positions(load_gltf(path, "", node_edits({e})).meshes[0], rz(45));
  // Any glTF rotation: its angles in this convention from glm's own extraction (Z * Y * X).
  const double w = std::sqrt(1 - 0.01 - 0.09 - 0.04);
  g.doc["nodes"][0]["rotation"] = {0.1, -0.3, 0.2, w};
  const std::string q = g.write(dir.path(), "q");
  double z = 0, y = 0, x = 0;
  glm::extractEulerAngleZYX(glm::mat4_cast(glm::dquat(w, 0.1, -0.3, 0.2)), z, y, x);
  e = node("Plate");
  e.rotation_rad[0] = 0.25;
  expect_positions(load_gltf(q, "", node_edits({e})).meshes[0], rz(z / kDeg) * ry(y / kDeg) * rx(0.25 / kDeg));
  // An edit that leaves the rotation alone keeps the glTF's quaternion: no bit changes.
  e = node("Plate");
  e.translation_m[0] = 0.0;
  EXPECT_EQ(load_gltf(q, "", node_edits({e})).meshes[0].positions, load_gltf(q).meshes[0].positions);
}

TEST(SceneEdits, ScaleComponentsReplaceTheGltfsPerAxis) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Plate"}, {"mesh", m}, {"scale", {1, 3, 1}}, {"translation", {0, 0, 1}}});
  const std::string path = g.write(dir.path(), "s");
  NodeEdit e = node("Plate");
  e.scale[0] = 2.0;
  const Scene s = load_gltf(path, "", node_edits({e}));
  expect_positions(s.meshes[0], glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, 1)) * glm::scale(glm::dmat4(1.0), glm::dvec3(2, 3, 1)));
  // A mirroring scale keeps the front side towards +Z, as a mirroring glTF node does.
  e.scale = {-1.0, std::nullopt, std::nullopt};
  const Scene mirrored = load_gltf(path, "", node_edits({e}));
  EXPECT_NEAR(face_normal(mirrored.meshes[0], 0).z, 1.0, 1e-9);
}

// The edit is of the node's local transform: its children, cameras and lights follow it.
TEST(SceneEdits, ChildrenCamerasAndLightsFollowTheirEditedParent) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.doc["cameras"] = {{{"type", "perspective"}, {"perspective", {{"yfov", 0.5}, {"znear", 0.01}}}}};
  g.doc["extensionsUsed"] = {"KHR_lights_punctual"};
  g.doc["extensions"] = {{"KHR_lights_punctual", {{"lights", {{{"type", "spot"}, {"intensity", 5}, {"spot", {{"outerConeAngle", 0.5}}}}}}}}};
  const int plate = g.node({{"name", "Plate"}, {"mesh", m}, {"translation", {0, 1, 0}}}, false);
  const int cam = g.node({{"name", "Cam"}, {"camera", 0}, {"translation", {0, 0, 2}}}, false);
  const int lamp = g.node({{"name", "Lamp"}, {"extensions", {{"KHR_lights_punctual", {{"light", 0}}}}}, {"translation", {1, 0, 0}}}, false);
  g.node({{"name", "Rig"}, {"translation", {0, 0, -1}}, {"children", {plate, cam, lamp}}});
  const std::string path = g.write(dir.path(), "rig");
  NodeEdit e = node("Rig");
  e.translation_m[0] = 0.5;
  e.rotation_rad[1] = 90 * kDeg;
  const Scene s = load_gltf(path, "", node_edits({e}));
  const glm::dmat4 rig = glm::translate(glm::dmat4(1.0), glm::dvec3(0.5, 0, -1)) * ry(90);
  expect_positions(s.meshes[0], rig * glm::translate(glm::dmat4(1.0), glm::dvec3(0, 1, 0)));
  ASSERT_EQ(s.cameras.size(), 1u);
  const glm::dvec3 cam_pos(s.cameras[0].world_from_camera[3]);
  expect_vec(glm::vec3(cam_pos), apply(rig, {0, 0, 2}), 1e-9);
  // The camera looks down its local -Z, turned by the rig's 90 degrees about Y: down -X.
  expect_vec(glm::vec3(glm::dmat3(s.cameras[0].world_from_camera) * glm::dvec3(0, 0, -1)), {-1, 0, 0}, 1e-9);
  const Light* l = s.find_light("Lamp");
  ASSERT_NE(l, nullptr);
  expect_vec(glm::vec3(l->position), apply(rig, {1, 0, 0}), 1e-9);
  expect_vec(glm::vec3(l->direction), {-1, 0, 0}, 1e-9);
  // The children's own transforms are not edited.
  EXPECT_EQ(glm::dvec3(s.nodes[static_cast<size_t>(plate)].world[3]), apply(rig, {0, 1, 0}));
}

// A node given as a matrix is decomposed into translation, rotation and scale, then edited.
TEST(SceneEdits, AMatrixNodeIsDecomposedThenEdited) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  const glm::dmat4 gltf = glm::translate(glm::dmat4(1.0), glm::dvec3(10, 0, 0)) * ry(30) * glm::scale(glm::dmat4(1.0), glm::dvec3(2, 2, 0.5));
  json matrix = json::array();
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) matrix.push_back(gltf[c][r]);
  const int child = g.node({{"name", "Child"}, {"mesh", m}, {"translation", {0, 1, 0}}}, false);
  g.node({{"name", "Parent"}, {"matrix", matrix}, {"children", {child}}});
  const std::string path = g.write(dir.path(), "matrix");
  const glm::dmat4 child_local = glm::translate(glm::dmat4(1.0), glm::dvec3(0, 1, 0));
  NodeEdit e = node("Parent");
  e.translation_m[1] = 5.0;
  expect_positions(load_gltf(path, "", node_edits({e})).meshes[0],
                   glm::translate(glm::dmat4(1.0), glm::dvec3(10, 5, 0)) * ry(30) * glm::scale(glm::dmat4(1.0), glm::dvec3(2, 2, 0.5)) * child_local);
  e = node("Parent");
  e.rotation_rad[1] = -45 * kDeg;  // x and z stay the matrix's (0)
  e.scale[2] = 1.0;
  expect_positions(load_gltf(path, "", node_edits({e})).meshes[0],
                   glm::translate(glm::dmat4(1.0), glm::dvec3(10, 0, 0)) * ry(-45) * glm::scale(glm::dmat4(1.0), glm::dvec3(2, 2, 1)) * child_local);
  // A mirroring matrix decomposes too (one negative scale) and keeps mirroring.
  const glm::dmat4 mirror = rz(20) * glm::scale(glm::dmat4(1.0), glm::dvec3(-1, 1, 1));
  for (int c = 0; c < 4; ++c)
    for (int r = 0; r < 4; ++r) g.doc["nodes"][1]["matrix"][size_t(4 * c + r)] = mirror[c][r];
  const std::string mirrored = g.write(dir.path(), "mirror");
  e = node("Parent");
  e.translation_m[2] = -3.0;
  expect_positions(load_gltf(mirrored, "", node_edits({e})).meshes[0],
                   glm::translate(glm::dmat4(1.0), glm::dvec3(0, 0, -3)) * mirror * child_local);
}

// A matrix with shear has no translation, rotation and scale to replace: an error naming the node. A
// rotation written in float (as exporters write matrices) is not shear.
TEST(SceneEdits, AShearingMatrixIsAnErrorNamingTheNode) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Sheared"}, {"mesh", m}, {"matrix", {1, 0, 0, 0, 0.01, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1}}});
  const std::string path = g.write(dir.path(), "shear");
  NodeEdit e = node("Sheared");
  e.translation_m[0] = 1.0;
  // unedited, it is rendered as given, and said (glTF 2.0 requires matrices without shear; it was silent)
  const Scene sheared = load_gltf(path);
  ASSERT_EQ(sheared.warnings.size(), 1u) << testing::PrintToString(sheared.warnings);
  EXPECT_THAT(sheared.warnings[0], HasSubstr("node 0 'Sheared': its matrix shears (recomposed from a translation, rotation and "
                                             "scale it differs by "));
  EXPECT_EQ(sheared.meshes[0].positions[2], glm::vec3(0.01f, 1, 0));  // (0, 1, 0) sheared along x
  const std::string msg = edit_error(path, node_edits({e}));
  EXPECT_THAT(msg, HasSubstr("node 0 'Sheared': its matrix is not a translation, rotation and scale (it shears"));
  EXPECT_THAT(msg, HasSubstr("/nodes/Sheared cannot replace"));
  g.doc["nodes"][0]["matrix"] = {0, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1};
  EXPECT_THAT(edit_error(g.write(dir.path(), "zero"), node_edits({e})), HasSubstr("its matrix has a zero scale"));
  json rounded = json::array();
  const glm::dmat4 r = rz(30);
  for (int c = 0; c < 4; ++c)
    for (int k = 0; k < 4; ++k) rounded.push_back(static_cast<double>(static_cast<float>(r[c][k])));
  g.doc["nodes"][0]["matrix"] = rounded;
  const Scene s = load_gltf(g.write(dir.path(), "float"), "", node_edits({e}));
  expect_positions(s.meshes[0], glm::translate(glm::dmat4(1.0), glm::dvec3(1, 0, 0)) * r);
  EXPECT_TRUE(load_gltf(g.write(dir.path(), "float")).warnings.empty()) << "a float rotation does not shear";
}

// Names are the glTF's: one that no element carries is an error naming the scene-file key, the glTF file,
// the closest name and the names there are; one that several carry names their indices.
TEST(SceneEdits, UnknownAndAmbiguousNamesAreErrorsNamingTheKeyAndTheFile) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Sphere"}, {"mesh", m}});
  g.node({{"name", "Plate"}, {"mesh", m}});
  g.node({{"name", "Cube.001"}, {"mesh", m}});
  g.node({{"name", "Cube.001"}, {"mesh", m}});
  g.node({{"mesh", m}});
  g.doc["materials"] = {{{"name", "Glass"}}, {{"name", "Glass"}}, {{"name", "Paper"}}};
  const std::string path = g.write(dir.path(), "names");
  std::string msg = edit_error(path, node_edits({node("Sphre")}));
  EXPECT_EQ(msg, "/nodes/Sphre: the glTF file " + path + " has no node named \"Sphre\"; did you mean \"Sphere\"? "
                 "(its nodes: \"Cube.001\", \"Plate\", \"Sphere\")");
  msg = edit_error(path, node_edits({node("Cube.001")}));
  EXPECT_EQ(msg, "/nodes/Cube.001: 2 nodes of the glTF file " + path + " are named \"Cube.001\" (nodes 2, 3); give them "
                 "distinct names in the glTF file to edit one");
  MaterialEdit glass, paper;
  glass.name = "Glass", paper.name = "paper";
  const std::string two = "/materials/Glass: 2 materials of the glTF file " + path;
  EXPECT_THAT(edit_error(path, {{}, {glass}}), HasSubstr(two + " are named \"Glass\" (materials 0, 1)"));
  EXPECT_THAT(edit_error(path, {{}, {paper}}), HasSubstr("has no material named \"paper\"; did you mean \"Paper\"?"));
  // An accented name spelt in another Unicode normalization (NFC "Caf\u00e9" against the glTF's NFD "Cafe\u0301")
  // printed alike in the suggestion: the code points tell them apart.
  {
    Gltf u;
    u.node({{"name", "Cafe\xcc\x81 table"}, {"mesh", u.triangle_mesh()}});
    EXPECT_THAT(edit_error(u.write(dir.path(), "nfd"), node_edits({node("Caf\xc3\xa9 table")})),
                HasSubstr("has no node named \"Caf\xc3\xa9 table\"; did you mean \"Cafe\xcc\x81 table\" (code points U+0043 U+0061 "
                          "U+0066 U+0065 U+0301 U+0020 U+0074 U+0061 U+0062 U+006C U+0065; you gave U+0043 U+0061 U+0066 U+00E9 "
                          "U+0020 U+0074 U+0061 U+0062 U+006C U+0065)?"));
  }
  // A name with '/' or '~' in the key as a JSON pointer writes it.
  EXPECT_THAT(edit_error(path, node_edits({node("a/b~c")})), HasSubstr("/nodes/a~1b~0c: the glTF file"));
  // Many names are not listed.
  for (char c = 'a'; c < 'a' + 20; ++c) g.node({{"name", std::string(3, c)}});
  EXPECT_THAT(edit_error(g.write(dir.path(), "many"), node_edits({node("Zzz")})),
              HasSubstr("has no node named \"Zzz\" (it has 23 named nodes; spadgen info lists them)"));
}

// Names hold whatever the glTF's hold: dots, spaces, slashes.
TEST(SceneEdits, NamesWithDotsSpacesAndSlashes) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Cube.001 / left"}, {"mesh", m}});
  const std::string path = g.write(dir.path(), "dots");
  NodeEdit e = node("Cube.001 / left");
  e.translation_m = {0.0, 1.0, 0.0};
  const Scene s = load_gltf(path, "", node_edits({e}));
  expect_positions(s.meshes[0], glm::translate(glm::dmat4(1.0), glm::dvec3(0, 1, 0)));
  EXPECT_THAT(spadgen::scenes::summarize(s), HasSubstr("nodes: 1\n  0 'Cube.001 / left', at (0, 1, 0)\n"));
}

// A material's edit replaces its factors; transmission > 0 on a material that declares no
// KHR_materials_transmission makes the same Material (what the renderer reads) as a glTF that declares it.
TEST(SceneEdits, MaterialEditsAreTheSameAsTheGltfGivingTheValues) {
  TempDir dir;
  Gltf declared, plain;
  for (Gltf* g : {&declared, &plain}) g->node({{"name", "Plate"}, {"mesh", g->triangle_mesh()}});
  declared.doc["extensionsUsed"] = {"KHR_materials_transmission", "KHR_materials_ior", "KHR_materials_volume"};
  declared.doc["materials"] = {{{"name", "PlateMaterial"},
                                {"pbrMetallicRoughness", {{"baseColorFactor", {0.9, 0.8, 0.7, 0.5}}, {"metallicFactor", 0.0}, {"roughnessFactor", 0.05}}},
                                {"extensions", {{"KHR_materials_transmission", {{"transmissionFactor", 0.95}}},
                                                {"KHR_materials_ior", {{"ior", 1.49}}},
                                                {"KHR_materials_volume", {{"thicknessFactor", 0.002}}}}}}};
  plain.doc["materials"] = {{{"name", "PlateMaterial"}, {"pbrMetallicRoughness", {{"baseColorFactor", {0.1, 0.2, 0.3, 0.5}}}}}};
  for (Gltf* g : {&declared, &plain}) g->doc["meshes"][0]["primitives"][0]["material"] = 0;
  const Scene want = load_gltf(declared.write(dir.path(), "declared"));
  MaterialEdit e;
  e.name = "PlateMaterial";
  e.base_color = {0.9, 0.8, 0.7};
  e.roughness = 0.05, e.metallic = 0.0, e.transmission = 0.95, e.ior = 1.49, e.thickness_m = 0.002;
  const std::string plain_path = plain.write(dir.path(), "plain");
  const Scene got = load_gltf(plain_path, "", {{}, {e}});
  ASSERT_EQ(got.materials.size(), 1u);
  const Material &a = got.materials[0], &b = want.materials[0];
  EXPECT_EQ(a.base_color, b.base_color);
  EXPECT_EQ(a.base_color.a, 0.5f) << "alpha is the glTF's";
  EXPECT_EQ(a.roughness, b.roughness);
  EXPECT_EQ(a.metallic, b.metallic);
  EXPECT_EQ(a.transmission, b.transmission);
  EXPECT_EQ(a.ior, b.ior);
  EXPECT_EQ(a.thickness_m, b.thickness_m);
  EXPECT_EQ(a.attenuation_distance_m, b.attenuation_distance_m);
  EXPECT_EQ(a.attenuation_color, b.attenuation_color);
  EXPECT_EQ(a.double_sided, b.double_sided);
  EXPECT_EQ(a.emissive, b.emissive);
  EXPECT_TRUE(a.transmissive());
  EXPECT_TRUE(got.has_transmission());
  // the edit adds no warning: both have only the open triangle's volume warning
  EXPECT_EQ(got.warnings, want.warnings);
  EXPECT_EQ(got.warnings.size(), 1u) << testing::PrintToString(got.warnings);
  // One component: the others stay the glTF's.
  MaterialEdit one;
  one.name = "PlateMaterial";
  one.base_color[1] = 1.0;
  EXPECT_EQ(load_gltf(plain_path, "", {{}, {one}}).materials[0].base_color, glm::vec4(0.1f, 1.0f, 0.3f, 0.5f));
}

// Edits that change nothing are warnings: a material no loaded mesh uses, a node of another glTF scene.
// An edit giving the glTF's own values is not.
TEST(SceneEdits, EditsThatChangeNothingAreWarnings) {
  TempDir dir;
  Gltf g;
  const int m = g.triangle_mesh();
  g.node({{"name", "Plate"}, {"mesh", m}, {"translation", {0, 0, -1}}});
  g.node({{"name", "Elsewhere"}, {"mesh", m}}, false);
  g.doc["scenes"].push_back({{"name", "other"}, {"nodes", {1}}});
  g.doc["materials"] = {{{"name", "Unused"}}};
  const std::string path = g.write(dir.path(), "unused");
  const Scene plain = load_gltf(path);
  NodeEdit same = node("Plate");
  same.translation_m[2] = -1.0;
  Scene s = load_gltf(path, "", node_edits({same}));
  EXPECT_TRUE(s.warnings.empty());
  EXPECT_EQ(s.meshes[0].positions, plain.meshes[0].positions) << "the glTF's own value changes no bit";
  MaterialEdit unused;
  unused.name = "Unused";
  unused.roughness = 0.5;
  s = load_gltf(path, "", {{node("Elsewhere")}, {unused}});
  EXPECT_TRUE(has_warning(s, "/materials/Unused: material 0 'Unused' is used by no mesh of the loaded scene; the edit changes nothing"));
  EXPECT_TRUE(has_warning(s, "/nodes/Elsewhere: node 1 'Elsewhere' is not part of the loaded glTF scene; the edit changes nothing"));
  EXPECT_THAT(spadgen::scenes::summarize(s), HasSubstr("1 'Elsewhere', not in the loaded scene"));
  EXPECT_FALSE(has_warning(load_gltf(path, "other", {{node("Elsewhere")}, {}}), "Elsewhere"));
}

}  // namespace
