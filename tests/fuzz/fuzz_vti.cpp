// libFuzzer target: parseVti and parseLegacyVtk on arbitrary bytes.
// Any exception other than lic::InputError, any crash or sanitizer report is a finding.
#include "vdbexport/io/FieldInput.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    const std::string_view bytes(reinterpret_cast<const char*>(data), size);
    try {
        vdbexport::parseVti(bytes, "fuzz.vti");
    } catch (const lic::InputError&) {
    }
    try {
        vdbexport::parseLegacyVtk(bytes, "fuzz.vtk");
    } catch (const lic::InputError&) {
    }
    return 0;
}
