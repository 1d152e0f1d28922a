// libFuzzer target: parseNpy on arbitrary bytes, and parseRaw with a shape taken from the input.
// Any exception other than lic::InputError, any crash or sanitizer report is a finding.
#include "vdbexport/io/FieldInput.h"

#include <lic/util/Error.h>

#include <cstdint>
#include <string_view>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size)
{
    const std::string_view bytes(reinterpret_cast<const char*>(data), size);
    try {
        vdbexport::parseNpy(bytes, "fuzz.npy");
    } catch (const lic::InputError&) {
    }
    if (size >= 3) {
        try {
            vdbexport::parseRaw(bytes.substr(3), {data[0] % 9 + 1, data[1] % 9 + 1, data[2] % 9 + 1},
                                (data[0] & 1) ? ">f8" : "float32", "fuzz.raw");
        } catch (const lic::InputError&) {
        }
    }
    return 0;
}
