// tinygltf 2.7 compiled from its Debian header, so that the fuzzer sees its coverage and the sanitizers check
// it (the program links Debian's shared libtinygltf instead). stb_image comes with it, as tinygltf refers to
// it, but decodes nothing: the loader's image callback decodes with libpng and libjpeg-turbo.
#define TINYGLTF_IMPLEMENTATION
#define STB_IMAGE_IMPLEMENTATION
#define STB_IMAGE_WRITE_IMPLEMENTATION
#include <tiny_gltf.h>
