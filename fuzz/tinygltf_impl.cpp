// tinygltf 2.7 and stb_image compiled from their Debian headers, so that the fuzzer sees their coverage
// and the sanitizers check them (the program links Debian's shared libtinygltf instead).
#define TINYGLTF_IMPLEMENTATION
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <tiny_gltf.h>
