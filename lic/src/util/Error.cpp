#include "lic/util/Error.h"
// Anchors the exception types in the library (nothing else to define).
