// NumPy .npy reader (format versions 1.0, 2.0, 3.0) and raw binary reader.
#include "io/DenseCommon.h"

#include <cctype>
#include <vector>

namespace vdbexport {

using namespace detail;

namespace {

/// The value of `key` in a Python dict literal such as
/// {'descr': '<f4', 'fortran_order': False, 'shape': (4, 5, 6, 3), }
std::string dictValue(const std::string& dict, const std::string& key, const std::string& source)
{
    std::size_t p = dict.find("'" + key + "'");
    if (p == std::string::npos) p = dict.find("\"" + key + "\"");
    if (p == std::string::npos) inputError(source, "the .npy header has no '" + key + "' entry: " + dict.substr(0, 120));
    p = dict.find(':', p + key.size() + 2);
    if (p == std::string::npos) inputError(source, "malformed .npy header near '" + key + "'");
    ++p;
    while (p < dict.size() && std::isspace(static_cast<unsigned char>(dict[p]))) ++p;
    if (p >= dict.size()) inputError(source, "malformed .npy header near '" + key + "'");
    std::size_t e = p;
    if (dict[p] == '\'' || dict[p] == '"') {
        e = dict.find(dict[p], p + 1);
        if (e == std::string::npos) inputError(source, "malformed .npy header: unterminated string for '" + key + "'");
        return dict.substr(p + 1, e - p - 1);
    }
    if (dict[p] == '(' || dict[p] == '[') {
        e = dict.find(dict[p] == '(' ? ')' : ']', p);
        if (e == std::string::npos) inputError(source, "malformed .npy header: unterminated shape");
        return dict.substr(p, e - p + 1);
    }
    while (e < dict.size() && dict[e] != ',' && dict[e] != '}') ++e;
    std::string v = dict.substr(p, e - p);
    while (!v.empty() && std::isspace(static_cast<unsigned char>(v.back()))) v.pop_back();
    return v;
}

std::vector<std::int64_t> parseShape(const std::string& text, const std::string& source)
{
    std::vector<std::int64_t> shape;
    std::size_t i = 1;
    while (i + 1 < text.size()) {
        while (i < text.size() && (std::isspace(static_cast<unsigned char>(text[i])) || text[i] == ',')) ++i;
        if (i + 1 >= text.size()) break;
        if (!std::isdigit(static_cast<unsigned char>(text[i])))
            inputError(source, "the .npy shape " + text.substr(0, 80) + " is not a tuple of non-negative integers");
        std::int64_t v = 0;
        while (i < text.size() && std::isdigit(static_cast<unsigned char>(text[i]))) {
            if (v > (std::int64_t(1) << 40)) inputError(source, "the .npy shape " + text.substr(0, 80) + " is too large");
            v = v * 10 + (text[i] - '0');
            ++i;
        }
        if (i < text.size() && text[i] == 'L') ++i; // Python 2 long
        shape.push_back(v);
        if (shape.size() > 8) inputError(source, "the .npy shape " + text.substr(0, 80) + " has too many dimensions");
    }
    return shape;
}

/// dtype text → element type and byte order. Accepts NumPy descr ('<f4', '>f8', '|u1', '=f4')
/// and names (float32, float64).
void parseDtype(const std::string& d, const std::string& source, Elem& elem, bool& bigEndian)
{
    std::string t = d;
    bigEndian = !hostIsLittle();
    if (t == "float32") t = "<f4";
    else if (t == "float64") t = "<f8";
    if (!t.empty() && (t[0] == '<' || t[0] == '>' || t[0] == '|' || t[0] == '=')) {
        if (t[0] == '>') bigEndian = true;
        else if (t[0] == '<') bigEndian = false;
        t = t.substr(1);
    } else if (t.size() == 2) {
        bigEndian = false;
    }
    static const std::pair<const char*, Elem> table[] = {
        {"f4", Elem::F32}, {"f8", Elem::F64}, {"i1", Elem::I8}, {"u1", Elem::U8}, {"i2", Elem::I16},
        {"u2", Elem::U16}, {"i4", Elem::I32}, {"u4", Elem::U32}, {"i8", Elem::I64}, {"u8", Elem::U64}};
    for (const auto& [name, e] : table) {
        if (t == name) {
            elem = e;
            return;
        }
    }
    inputError(source, "unsupported dtype '" + d.substr(0, 40)
                           + "'; expected float32 or float64 ('<f4', '<f8', '>f4', '>f8') or an integer type");
}

/// Fill `out` (x fastest, components interleaved) from an n-d array with the given element
/// strides: value (i,j,k,c) is element `i*si + j*sj + k*sk + c*sc`.
DenseImage gather(const unsigned char* data, Elem elem, bool swap, const std::array<std::int64_t, 3>& dims,
                  int components, std::int64_t si, std::int64_t sj, std::int64_t sk, std::int64_t sc)
{
    DenseImage img;
    img.dims = dims;
    DenseImage::Array arr;
    arr.name = components == 3 ? "velocity" : "scalar";
    arr.components = components;
    arr.data.resize(img.voxelCount() * std::size_t(components));
    std::size_t o = 0;
    for (std::int64_t k = 0; k < dims[2]; ++k)
        for (std::int64_t j = 0; j < dims[1]; ++j)
            for (std::int64_t i = 0; i < dims[0]; ++i)
                for (int c = 0; c < components; ++c)
                    arr.data[o++] = loadElem(data, elem, swap, std::size_t(i * si + j * sj + k * sk + c * sc));
    img.arrays.push_back(std::move(arr));
    return img;
}

/// Build from an n-d array of `shape` (already validated as 3-d or 4-d) with C or Fortran order.
DenseImage fromArray(const unsigned char* data, std::size_t available, Elem elem, bool bigEndian, bool fortran,
                     const std::vector<std::int64_t>& shape, const std::string& source)
{
    std::array<std::int64_t, 3> dims{};
    int components = 1;
    int spatialAxis0 = 0; // index in shape of X
    int compAxis = -1;
    if (shape.size() == 3) {
        dims = {shape[0], shape[1], shape[2]};
    } else if (shape.size() == 4 && shape[3] == 3) {
        dims = {shape[0], shape[1], shape[2]};
        components = 3;
        compAxis = 3;
    } else if (shape.size() == 4 && shape[0] == 3) {
        dims = {shape[1], shape[2], shape[3]};
        components = 3;
        compAxis = 0;
        spatialAxis0 = 1;
    } else {
        std::string s = "(";
        for (std::size_t i = 0; i < shape.size(); ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
        inputError(source, "unsupported array shape " + s + ")" + (shape.size() == 1 ? "," : "")
                               + "; expected (X, Y, Z, 3) or (3, X, Y, Z) for a vector field, or (X, Y, Z) for a scalar");
    }
    checkDims(dims, source);
    const std::uint64_t count = std::uint64_t(dims[0]) * std::uint64_t(dims[1]) * std::uint64_t(dims[2]) * std::uint64_t(components);
    const std::uint64_t need = count * elemSize(elem);
    if (need > available)
        inputError(source, "the header declares shape with " + std::to_string(count) + " values (" + std::to_string(need)
                               + " bytes) but the file holds only " + std::to_string(available)
                               + " bytes of data (truncated, or a wrong header)");
    if (need < available)
        inputError(source, "the file holds " + std::to_string(available) + " bytes of data but the header declares "
                               + std::to_string(need) + " bytes; expected exactly one array");
    // Element strides for each axis of `shape`.
    const std::size_t nd = shape.size();
    std::vector<std::int64_t> stride(nd, 1);
    if (fortran) {
        for (std::size_t a = 1; a < nd; ++a) stride[a] = stride[a - 1] * shape[a - 1];
    } else {
        for (std::size_t a = nd - 1; a-- > 0;) stride[a] = stride[a + 1] * shape[a + 1];
    }
    const std::int64_t si = stride[spatialAxis0], sj = stride[spatialAxis0 + 1], sk = stride[spatialAxis0 + 2];
    const std::int64_t sc = compAxis >= 0 ? stride[compAxis] : 0;
    return gather(data, elem, bigEndian == hostIsLittle(), dims, components, si, sj, sk, sc);
}

} // namespace

NpyArray detail::parseNpyArray(std::string_view bytes, const std::string& source)
{
    static const char magic[] = "\x93NUMPY";
    if (bytes.size() < 10 || bytes.compare(0, 6, std::string_view(magic, 6)) != 0)
        inputError(source, "not a NumPy .npy file (no \\x93NUMPY magic); expected an array saved with numpy.save");
    const auto* u = reinterpret_cast<const unsigned char*>(bytes.data());
    const int major = u[6];
    std::size_t headerLen = 0, headerStart = 0;
    if (major == 1) {
        headerLen = std::size_t(u[8]) | (std::size_t(u[9]) << 8);
        headerStart = 10;
    } else if (major == 2 || major == 3) {
        if (bytes.size() < 12) inputError(source, "the .npy header is cut short");
        headerLen = std::size_t(u[8]) | (std::size_t(u[9]) << 8) | (std::size_t(u[10]) << 16) | (std::size_t(u[11]) << 24);
        headerStart = 12;
    } else {
        inputError(source, "unsupported .npy format version " + std::to_string(major) + "."
                               + std::to_string(int(u[7])) + "; expected 1.0, 2.0 or 3.0");
    }
    if (headerLen > bytes.size() - headerStart)
        inputError(source, "the .npy header is cut short (declares " + std::to_string(headerLen) + " bytes, the file has "
                               + std::to_string(bytes.size()) + ")");
    const std::string dict(bytes.substr(headerStart, headerLen));
    if (dict.find('{') == std::string::npos || dict.find('}') == std::string::npos)
        inputError(source, "malformed .npy header (no dict): " + dict.substr(0, 80));
    const std::string descr = dictValue(dict, "descr", source);
    const std::string fortranText = dictValue(dict, "fortran_order", source);
    const std::string shapeText = dictValue(dict, "shape", source);
    NpyArray a;
    if (fortranText == "True") a.fortran = true;
    else if (fortranText != "False")
        inputError(source, "malformed .npy header: fortran_order is '" + fortranText.substr(0, 20) + "'; expected True or False");
    if (shapeText.empty() || shapeText[0] != '(')
        inputError(source, "malformed .npy header: shape is '" + shapeText.substr(0, 40) + "'; expected a tuple");
    parseDtype(descr, source, a.elem, a.bigEndian);
    a.descr = descr;
    a.shape = parseShape(shapeText, source);
    const std::size_t dataStart = headerStart + headerLen;
    a.data = u + dataStart;
    a.available = bytes.size() - dataStart;
    return a;
}

DenseImage parseNpy(std::string_view bytes, const std::string& source)
{
    const NpyArray a = parseNpyArray(bytes, source);
    return fromArray(a.data, a.available, a.elem, a.bigEndian, a.fortran, a.shape, source);
}

DenseImage parseRaw(std::string_view bytes, const std::array<std::int64_t, 3>& shape, const std::string& dtype,
                    const std::string& source)
{
    Elem elem;
    bool big;
    parseDtype(dtype, source, elem, big);
    if (elem != Elem::F32 && elem != Elem::F64)
        inputError(source, "raw dtype '" + dtype + "' is not supported; expected float32 or float64");
    checkDims(shape, source);
    const std::uint64_t need = std::uint64_t(shape[0]) * std::uint64_t(shape[1]) * std::uint64_t(shape[2]) * 3 * elemSize(elem);
    if (need != bytes.size())
        inputError(source, "the raw file has " + std::to_string(bytes.size()) + " bytes but shape " + std::to_string(shape[0])
                               + "," + std::to_string(shape[1]) + "," + std::to_string(shape[2]) + " x 3 components of "
                               + dtype + " needs " + std::to_string(need) + " bytes; check --shape and --dtype");
    return fromArray(reinterpret_cast<const unsigned char*>(bytes.data()), bytes.size(), elem, big, false,
                     {shape[0], shape[1], shape[2], 3}, source);
}

} // namespace vdbexport
