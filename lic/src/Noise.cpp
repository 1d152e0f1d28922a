#include "lic/Noise.h"
// Header-only; this file keeps the build list stable and checks the header compiles alone.
