// VTK image data readers: XML ImageData (.vti) and legacy STRUCTURED_POINTS (.vtk).
#include "io/DenseCommon.h"

#include <zlib.h>

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <map>
#include <optional>
#include <sstream>

namespace vdbexport {

using namespace detail;

namespace {

// ---- small XML tag scanner ---------------------------------------------------------------

struct Tag
{
    std::string name;                          // "DataArray", "/PointData"
    std::map<std::string, std::string> attrs;
    std::size_t begin = 0, end = 0;            // [begin, end) of "<...>"
    bool selfClosing = false;
};

/// The next tag at or after `pos` (skipping <?xml ?> and comments), or nullopt.
std::optional<Tag> nextTag(std::string_view s, std::size_t pos, const std::string& source)
{
    while (true) {
        const std::size_t lt = s.find('<', pos);
        if (lt == std::string_view::npos) return std::nullopt;
        if (s.compare(lt, 4, "<!--") == 0) {
            const std::size_t e = s.find("-->", lt + 4);
            if (e == std::string_view::npos) inputError(source, "unterminated XML comment");
            pos = e + 3;
            continue;
        }
        const std::size_t gt = s.find('>', lt);
        if (gt == std::string_view::npos) inputError(source, "unterminated XML tag at byte " + std::to_string(lt));
        if (s[lt + 1] == '?' || s[lt + 1] == '!') {
            pos = gt + 1;
            continue;
        }
        Tag t;
        t.begin = lt;
        t.end = gt + 1;
        std::size_t i = lt + 1;
        while (i < gt && !std::isspace(static_cast<unsigned char>(s[i])) && s[i] != '/' ) ++i;
        if (i == lt + 1 && s[i] == '/') { // closing tag
            ++i;
            while (i < gt && !std::isspace(static_cast<unsigned char>(s[i]))) ++i;
            t.name = "/" + std::string(s.substr(lt + 2, i - lt - 2));
            return t;
        }
        t.name = std::string(s.substr(lt + 1, i - lt - 1));
        while (i < gt) {
            while (i < gt && std::isspace(static_cast<unsigned char>(s[i]))) ++i;
            if (i >= gt) break;
            if (s[i] == '/') {
                t.selfClosing = true;
                ++i;
                continue;
            }
            const std::size_t eq = s.find('=', i);
            if (eq == std::string_view::npos || eq > gt) inputError(source, "malformed XML attribute in <" + t.name + ">");
            std::string key(s.substr(i, eq - i));
            while (!key.empty() && std::isspace(static_cast<unsigned char>(key.back()))) key.pop_back();
            std::size_t v = eq + 1;
            while (v < gt && std::isspace(static_cast<unsigned char>(s[v]))) ++v;
            if (v >= gt || (s[v] != '"' && s[v] != '\'')) inputError(source, "malformed XML attribute " + key + " in <" + t.name + ">");
            const std::size_t ve = s.find(s[v], v + 1);
            if (ve == std::string_view::npos || ve > gt) inputError(source, "unterminated XML attribute " + key + " in <" + t.name + ">");
            t.attrs[key] = std::string(s.substr(v + 1, ve - v - 1));
            i = ve + 1;
        }
        return t;
    }
}

/// Call `f(v)` for each whitespace-separated number v of `text`, in order, until `f` returns false.
/// @return false at a word that is not a number.
template<class F>
bool forEachNumber(const char* p, F&& f)
{
    char* end = nullptr;
    while (true) {
        while (*p && std::isspace(static_cast<unsigned char>(*p))) ++p;
        if (!*p) return true;
        const double v = std::strtod(p, &end);
        if (end == p) return false;
        if (!f(v)) return true;
        p = end;
    }
}

/// Exactly `expected` numbers of attribute `what`.
std::vector<double> numbers(const std::string& text, std::size_t expected, const std::string& what, const std::string& source)
{
    std::vector<double> out;
    const bool numeric = forEachNumber(text.c_str(), [&](double v) {
        out.push_back(v);
        return out.size() <= expected;
    });
    if (!numeric) inputError(source, what + " '" + text.substr(0, 60) + "' is not a list of numbers");
    if (out.size() != expected)
        inputError(source, what + " '" + text.substr(0, 60) + "' needs " + std::to_string(expected) + " numbers");
    return out;
}

Elem vtkType(const std::string& t, const std::string& source)
{
    static const std::pair<const char*, Elem> table[] = {
        {"Float32", Elem::F32}, {"Float64", Elem::F64}, {"Int8", Elem::I8},   {"UInt8", Elem::U8},
        {"Int16", Elem::I16},   {"UInt16", Elem::U16},  {"Int32", Elem::I32}, {"UInt32", Elem::U32},
        {"Int64", Elem::I64},   {"UInt64", Elem::U64}};
    for (const auto& [n, e] : table)
        if (t == n) return e;
    inputError(source, "unsupported DataArray type '" + t.substr(0, 40) + "'; expected Float32 or Float64");
}

/// Base64 decoded group by group, so separately padded pieces (VTK encodes the header and
/// the data of a binary array separately) concatenate correctly.
std::string base64Decode(std::string_view text, const std::string& source)
{
    static const auto value = [](char c) -> int {
        if (c >= 'A' && c <= 'Z') return c - 'A';
        if (c >= 'a' && c <= 'z') return c - 'a' + 26;
        if (c >= '0' && c <= '9') return c - '0' + 52;
        if (c == '+') return 62;
        if (c == '/') return 63;
        if (c == '=') return -2;
        return -1;
    };
    std::string out;
    out.reserve(text.size() / 4 * 3);
    int group[4];
    int n = 0;
    for (char c : text) {
        const int v = value(c);
        if (v == -1) {
            if (std::isspace(static_cast<unsigned char>(c))) continue;
            inputError(source, "invalid character in base64 data");
        }
        group[n++] = v;
        if (n < 4) continue;
        n = 0;
        if (group[0] < 0 || group[1] < 0) inputError(source, "malformed base64 padding");
        const unsigned b0 = unsigned(group[0]), b1 = unsigned(group[1]);
        out.push_back(char((b0 << 2) | (b1 >> 4)));
        if (group[2] < 0) continue;
        out.push_back(char(((b1 & 15) << 4) | (unsigned(group[2]) >> 2)));
        if (group[3] < 0) continue;
        out.push_back(char(((unsigned(group[2]) & 3) << 6) | unsigned(group[3])));
    }
    if (n != 0) inputError(source, "base64 data length is not a multiple of 4");
    return out;
}

struct BinaryFormat
{
    bool headerUInt64 = false;
    bool zlib = false;
    bool bigEndian = false;
};

std::uint64_t readHeaderWord(std::string_view b, std::size_t at, const BinaryFormat& f, const std::string& source)
{
    const std::size_t w = f.headerUInt64 ? 8 : 4;
    if (at + w > b.size()) inputError(source, "binary DataArray header is cut short");
    const auto* u = reinterpret_cast<const unsigned char*>(b.data());
    std::uint64_t v = 0;
    for (std::size_t i = 0; i < w; ++i) {
        const std::size_t idx = f.bigEndian ? at + i : at + w - 1 - i;
        v = (v << 8) | u[idx];
    }
    return v;
}

/// Decode one binary block stream (header + data) into raw array bytes; `need` is the expected
/// byte count (checked before any decompression buffer is allocated). `used` receives the
/// number of input bytes consumed.
std::string decodeBlocks(std::string_view b, const BinaryFormat& f, std::uint64_t need, const std::string& source,
                         std::size_t* used = nullptr)
{
    const std::size_t w = f.headerUInt64 ? 8 : 4;
    if (!f.zlib) {
        const std::uint64_t n = readHeaderWord(b, 0, f, source);
        if (n != need)
            inputError(source, "a binary DataArray holds " + std::to_string(n) + " bytes; the extent and components need "
                                   + std::to_string(need) + " (mismatched shape)");
        if (n > b.size() - w) inputError(source, "a binary DataArray is cut short (declares " + std::to_string(n) + " bytes)");
        if (used) *used = w + n;
        return std::string(b.substr(w, n));
    }
    const std::uint64_t blocks = readHeaderWord(b, 0, f, source);
    const std::uint64_t blockSize = readHeaderWord(b, w, f, source);
    const std::uint64_t lastSize = readHeaderWord(b, 2 * w, f, source);
    if (blocks > b.size() / w) inputError(source, "compressed DataArray header declares too many blocks");
    const std::uint64_t total = blocks == 0 ? 0 : (blocks - 1) * blockSize + (lastSize == 0 ? blockSize : lastSize);
    if (blocks > 0 && (blockSize == 0 || blockSize > (std::uint64_t(1) << 32)))
        inputError(source, "compressed DataArray header has a bad block size");
    if (total != need)
        inputError(source, "a compressed DataArray holds " + std::to_string(total) + " bytes; the extent and components need "
                               + std::to_string(need) + " (mismatched shape)");
    std::size_t pos = (3 + std::size_t(blocks)) * w;
    if (pos > b.size()) inputError(source, "compressed DataArray header is cut short");
    std::string out;
    out.reserve(need);
    for (std::uint64_t i = 0; i < blocks; ++i) {
        const std::uint64_t csize = readHeaderWord(b, (3 + std::size_t(i)) * w, f, source);
        if (csize > b.size() - pos) inputError(source, "compressed DataArray is cut short");
        const std::uint64_t usize = (i + 1 == blocks && lastSize != 0) ? lastSize : blockSize;
        std::string block(usize, '\0');
        uLongf destLen = uLongf(usize);
        const int rc = ::uncompress(reinterpret_cast<Bytef*>(block.data()), &destLen,
                                    reinterpret_cast<const Bytef*>(b.data() + pos), uLong(csize));
        if (rc != Z_OK || destLen != usize) inputError(source, "zlib data of a DataArray is corrupt");
        out += block;
        pos += csize;
    }
    if (used) *used = pos;
    return out;
}

void storeArray(DenseImage& img, const std::string& name, int comps, std::string_view bytes, Elem e, bool big)
{
    DenseImage::Array a;
    a.name = name;
    a.components = comps;
    const std::size_t n = bytes.size() / elemSize(e);
    a.data.resize(n);
    const auto* u = reinterpret_cast<const unsigned char*>(bytes.data());
    const bool swap = big == hostIsLittle();
    for (std::size_t i = 0; i < n; ++i) a.data[i] = loadElem(u, e, swap, i);
    img.arrays.push_back(std::move(a));
}

/// Turn cell dims/point dims: `cells` = true when the arrays are CellData.
void finishGeometry(DenseImage& img, const std::array<std::int64_t, 6>& ext, bool cells, const std::string& source)
{
    std::array<std::int64_t, 3> d{};
    for (int a = 0; a < 3; ++a) d[a] = ext[2 * a + 1] - ext[2 * a] + (cells ? 0 : 1);
    if (cells)
        for (int a = 0; a < 3; ++a) d[a] = std::max<std::int64_t>(d[a], 1);
    checkDims(d, source);
    img.dims = d;
    for (int a = 0; a < 3; ++a) {
        if (!(img.spacing[a] > 0) || !std::isfinite(img.spacing[a]))
            inputError(source, "spacing " + std::to_string(img.spacing[a]) + " on axis " + std::string(1, "xyz"[a])
                                   + " is not positive; expected a voxel size > 0");
        img.origin[a] += (double(ext[2 * a]) + (cells ? 0.5 : 0.0)) * img.spacing[a];
    }
}

/// The binary layout a <VTKFile> element declares (byte order, header word size, compressor).
BinaryFormat binaryFormat(const Tag& file, const std::string& source)
{
    auto attr = [&](const char* name) {
        const auto it = file.attrs.find(name);
        return it == file.attrs.end() ? std::optional<std::string>() : it->second;
    };
    if (attr("type") && *attr("type") != "ImageData")
        inputError(source, "VTK XML type '" + *attr("type") + "' is not supported; expected ImageData");
    BinaryFormat bf;
    bf.bigEndian = attr("byte_order") == "BigEndian";
    if (const auto header = attr("header_type")) {
        if (*header == "UInt64") bf.headerUInt64 = true;
        else if (*header != "UInt32")
            inputError(source, "header_type '" + *header + "' is not supported; expected UInt32 or UInt64");
    }
    if (const auto compressor = attr("compressor"); compressor && !compressor->empty()) {
        if (*compressor != "vtkZLibDataCompressor")
            inputError(source, "compressor '" + *compressor + "' is not supported; expected vtkZLibDataCompressor or none");
        bf.zlib = true;
    }
    return bf;
}

/// One pass over the tags of a .vti file, filling a DenseImage.
class VtiParser
{
public:
    VtiParser(std::string_view s, const std::string& source) : mS(s), mSource(source) { mImg.hasGeometry = true; }

    DenseImage parse();

private:
    /// An appended DataArray: its bytes are in <AppendedData> at `offset`.
    struct Pending
    {
        std::string name;
        int comps;
        Elem e;
        std::uint64_t offset;
    };

    void readImageData(const Tag& tag);
    void readPiece(const Tag& tag);
    void readDataSection(const Tag& tag);
    void readDataArray(const Tag& tag);
    void readAsciiArray(const std::string& name, int comps, std::uint64_t values, std::string_view body);
    void readAppendedArrays();
    std::vector<double> attrNumbers(const Tag& tag, const char* name, std::size_t count) const
    {
        return numbers(tag.attrs.at(name), count, name, mSource);
    }

    std::string_view mS;
    const std::string& mSource;
    BinaryFormat mFormat;
    DenseImage mImg;
    std::array<std::int64_t, 6> mExtent{};
    bool mHaveExtent = false, mInPiece = false, mCells = false, mSawData = false;
    int mPieces = 0;
    std::size_t mPos = 0; ///< where the next tag is looked for
    std::vector<Pending> mAppended;
    std::string mAppendedEncoding;
    std::size_t mAppendedStart = std::string_view::npos;
};

DenseImage VtiParser::parse()
{
    const auto file = nextTag(mS, 0, mSource);
    if (!file || file->name != "VTKFile") inputError(mSource, "not a VTK XML file (no <VTKFile> element); expected a .vti file");
    mFormat = binaryFormat(*file, mSource);
    mPos = file->end;
    while (auto tag = nextTag(mS, mPos, mSource)) {
        mPos = tag->end;
        if (tag->name == "ImageData") readImageData(*tag);
        else if (tag->name == "Piece") readPiece(*tag);
        else if (tag->name == "PointData" || tag->name == "CellData") readDataSection(*tag);
        else if (tag->name == "DataArray") readDataArray(*tag);
        else if (tag->name == "AppendedData") {
            mAppendedEncoding = tag->attrs.count("encoding") ? tag->attrs.at("encoding") : "raw";
            const std::size_t us = mS.find('_', tag->end);
            if (us == std::string_view::npos) inputError(mSource, "<AppendedData> has no '_' marker");
            mAppendedStart = us + 1;
            break; // raw bytes follow: stop scanning tags
        }
    }
    if (!mHaveExtent) inputError(mSource, "no <ImageData WholeExtent=...> element; expected a .vti ImageData file");
    if (!mSawData) inputError(mSource, "no <PointData> or <CellData> arrays");
    if (!mAppended.empty()) readAppendedArrays();
    if (mImg.arrays.empty()) inputError(mSource, "no DataArray in the file");
    return std::move(mImg);
}

void VtiParser::readImageData(const Tag& tag)
{
    const auto& a = tag.attrs;
    if (!a.count("WholeExtent")) inputError(mSource, "<ImageData> has no WholeExtent");
    const auto e = attrNumbers(tag, "WholeExtent", 6);
    for (int i = 0; i < 6; ++i) {
        if (std::fabs(e[i]) > 1e12 || e[i] != std::floor(e[i])) inputError(mSource, "WholeExtent has a non-integer or huge value");
        mExtent[i] = std::int64_t(e[i]);
    }
    mHaveExtent = true;
    if (a.count("Origin")) {
        const auto o = attrNumbers(tag, "Origin", 3);
        mImg.origin = openvdb::Vec3d(o[0], o[1], o[2]);
    }
    if (a.count("Spacing")) {
        const auto sp = attrNumbers(tag, "Spacing", 3);
        mImg.spacing = openvdb::Vec3d(sp[0], sp[1], sp[2]);
    }
    if (a.count("Direction")) {
        const auto d = attrNumbers(tag, "Direction", 9);
        const double id[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};
        for (int i = 0; i < 9; ++i)
            if (std::fabs(d[i] - id[i]) > 1e-9) inputError(mSource, "a rotated ImageData (Direction not identity) is not supported");
    }
}

void VtiParser::readPiece(const Tag& tag)
{
    if (++mPieces > 1) inputError(mSource, "several <Piece> elements; expected one piece (merge the pieces first)");
    mInPiece = true;
    if (tag.attrs.count("Extent")) {
        const auto e = attrNumbers(tag, "Extent", 6);
        for (int i = 0; i < 6; ++i)
            if (double(mExtent[i]) != e[i]) inputError(mSource, "piece Extent differs from WholeExtent; expected one whole piece");
    }
}

/// <PointData> or <CellData>: the first one fixes the geometry; arrays of the other kind are
/// skipped.
void VtiParser::readDataSection(const Tag& tag)
{
    if (!mHaveExtent) inputError(mSource, "<" + tag.name + "> before <ImageData WholeExtent=...>");
    if (mSawData && mCells != (tag.name == "CellData")) {
        const std::size_t close = mS.find("</" + tag.name + ">", mPos);
        if (close == std::string_view::npos) inputError(mSource, "unterminated <" + tag.name + ">");
        mPos = close;
        return;
    }
    if (!mSawData) {
        mCells = tag.name == "CellData";
        mSawData = true;
        finishGeometry(mImg, mExtent, mCells, mSource);
    }
}

void VtiParser::readDataArray(const Tag& tag)
{
    if (!mSawData || !mInPiece) inputError(mSource, "<DataArray> outside <PointData>/<CellData> of a <Piece>");
    const auto& a = tag.attrs;
    const std::string name = a.count("Name") ? a.at("Name") : "array" + std::to_string(mImg.arrays.size());
    const Elem e = vtkType(a.count("type") ? a.at("type") : "", mSource);
    int comps = 1;
    if (a.count("NumberOfComponents")) {
        comps = std::atoi(a.at("NumberOfComponents").c_str());
        if (comps != 1 && comps != 3)
            inputError(mSource, "DataArray " + q(name) + " has " + a.at("NumberOfComponents") + " components; expected 1 or 3");
    }
    const std::uint64_t values = mImg.voxelCount() * std::uint64_t(comps);
    const std::string format = a.count("format") ? a.at("format") : "ascii";
    const std::size_t close = tag.selfClosing ? mPos : mS.find("</DataArray>", mPos);
    if (close == std::string_view::npos) inputError(mSource, "unterminated <DataArray> " + q(name));
    const std::string_view body = mS.substr(mPos, close - mPos);
    if (format == "ascii") {
        readAsciiArray(name, comps, values, body);
    } else if (format == "binary") {
        const std::string raw = base64Decode(body, mSource);
        storeArray(mImg, name, comps, decodeBlocks(raw, mFormat, values * elemSize(e), mSource), e, mFormat.bigEndian);
    } else if (format == "appended") {
        if (!a.count("offset")) inputError(mSource, "appended DataArray " + q(name) + " has no offset");
        char* end = nullptr;
        const unsigned long long off = std::strtoull(a.at("offset").c_str(), &end, 10);
        mAppended.push_back({name, comps, e, off});
    } else {
        inputError(mSource, "DataArray " + q(name) + " has format '" + format + "'; expected ascii, binary or appended");
    }
    mPos = close;
}

void VtiParser::readAsciiArray(const std::string& name, int comps, std::uint64_t values, std::string_view body)
{
    if (values > body.size() / 2 + 1)
        inputError(mSource, "DataArray " + q(name) + " has too few values for the extent (" + std::to_string(values)
                                + " needed; mismatched shape)");
    DenseImage::Array arr;
    arr.name = name;
    arr.components = comps;
    arr.data.reserve(values);
    const std::string text(body);
    const bool numeric = forEachNumber(text.c_str(), [&](double v) {
        if (arr.data.size() == values)
            inputError(mSource, "DataArray " + q(name) + " has more values than the extent needs ("
                                    + std::to_string(values) + "; mismatched shape)");
        arr.data.push_back(float(v));
        return true;
    });
    if (!numeric) inputError(mSource, "DataArray " + q(name) + " has a value that is not a number");
    if (arr.data.size() != values)
        inputError(mSource, "DataArray " + q(name) + " has " + std::to_string(arr.data.size()) + " values; the extent needs "
                                + std::to_string(values) + " (mismatched shape)");
    mImg.arrays.push_back(std::move(arr));
}

void VtiParser::readAppendedArrays()
{
    if (mAppendedStart == std::string_view::npos) inputError(mSource, "appended DataArrays but no <AppendedData> section");
    if (mAppendedEncoding != "raw" && mAppendedEncoding != "base64")
        inputError(mSource, "AppendedData encoding '" + mAppendedEncoding + "' is not supported; expected raw or base64");
    const std::string_view data = mS.substr(mAppendedStart);
    for (const auto& p : mAppended) {
        const std::uint64_t need = mImg.voxelCount() * std::uint64_t(p.comps) * elemSize(p.e);
        if (p.offset > data.size()) inputError(mSource, "appended DataArray " + q(p.name) + " offset is past the end of the file");
        if (mAppendedEncoding == "raw") {
            storeArray(mImg, p.name, p.comps, decodeBlocks(data.substr(p.offset), mFormat, need, mSource), p.e, mFormat.bigEndian);
            continue;
        }
        // base64: the offset counts encoded characters. This array ends where the next one begins,
        // which we cannot know without the header: decode everything up to '<' and use the front.
        std::string_view rest = data.substr(p.offset);
        rest = rest.substr(0, rest.find('<'));
        const std::string raw = base64Decode(rest, mSource);
        storeArray(mImg, p.name, p.comps, decodeBlocks(raw, mFormat, need, mSource), p.e, mFormat.bigEndian);
    }
}

} // namespace

DenseImage parseVti(std::string_view s, const std::string& source) { return VtiParser(s, source).parse(); }

// ---- legacy .vtk -------------------------------------------------------------------------

namespace {

/// A cursor over a legacy VTK file: lines and whitespace-separated words.
struct LegacyCursor
{
    std::string_view s;
    std::size_t pos = 0;
    const std::string& source;

    std::string line()
    {
        if (pos >= s.size()) inputError(source, "unexpected end of file");
        std::size_t e = s.find('\n', pos);
        if (e == std::string_view::npos) e = s.size();
        std::string l(s.substr(pos, e - pos));
        pos = std::min(s.size(), e + 1);
        if (!l.empty() && l.back() == '\r') l.pop_back();
        return l;
    }
    /// Next non-blank word, or "" at the end.
    std::string word()
    {
        while (pos < s.size() && std::isspace(static_cast<unsigned char>(s[pos]))) ++pos;
        std::size_t e = pos;
        while (e < s.size() && !std::isspace(static_cast<unsigned char>(s[e]))) ++e;
        std::string w(s.substr(pos, e - pos));
        pos = e;
        return w;
    }
    double number(const std::string& what)
    {
        const std::string w = word();
        char* end = nullptr;
        const double v = std::strtod(w.c_str(), &end);
        if (w.empty() || *end) inputError(source, what + ": '" + w.substr(0, 40) + "' is not a number");
        return v;
    }
    /// Skip the rest of the current line (after the last word read).
    void endLine()
    {
        const std::size_t e = s.find('\n', pos);
        pos = e == std::string_view::npos ? s.size() : e + 1;
    }
};

std::string upper(std::string w)
{
    for (auto& c : w) c = char(std::toupper(static_cast<unsigned char>(c)));
    return w;
}

/// A VECTORS, SCALARS or NORMALS section (`key`) after its keyword: name, type, values.
void readLegacyArray(LegacyCursor& c, DenseImage& img, const std::string& key, bool binary)
{
    const std::string name = c.word();
    const std::string type = c.word();
    int comps = key == "SCALARS" ? 1 : 3;
    if (key == "SCALARS") {
        // optional numComp on the same line
        const std::size_t save = c.pos;
        const std::size_t eol = c.s.find('\n', c.pos);
        const std::string rest(c.s.substr(c.pos, (eol == std::string_view::npos ? c.s.size() : eol) - c.pos));
        const int nc = std::atoi(rest.c_str());
        if (nc == 3) comps = 3;
        else if (nc > 1) inputError(c.source, "SCALARS " + q(name) + " with " + std::to_string(nc) + " components; expected 1 or 3");
        c.pos = save;
        c.endLine();
        // LOOKUP_TABLE line
        const std::size_t before = c.pos;
        if (upper(c.word()) == "LOOKUP_TABLE") c.endLine();
        else c.pos = before;
    } else {
        c.endLine();
    }
    Elem e;
    const std::string t = upper(type);
    if (t == "FLOAT") e = Elem::F32;
    else if (t == "DOUBLE") e = Elem::F64;
    else inputError(c.source, key + " " + q(name) + " has type '" + type.substr(0, 20) + "'; expected float or double");
    const std::uint64_t values = img.voxelCount() * std::uint64_t(comps);
    if (binary) {
        const std::uint64_t need = values * elemSize(e);
        if (need > c.s.size() - c.pos)
            inputError(c.source, key + " " + q(name) + " is cut short: needs " + std::to_string(need) + " bytes, "
                                     + std::to_string(c.s.size() - c.pos) + " left (truncated or mismatched shape)");
        storeArray(img, name, comps, c.s.substr(c.pos, need), e, /*big=*/true);
        c.pos += need;
    } else {
        if (values > (c.s.size() - c.pos) / 2 + 1)
            inputError(c.source, key + " " + q(name) + " has too few values for DIMENSIONS (mismatched shape or truncated)");
        DenseImage::Array arr;
        arr.name = name;
        arr.components = comps;
        arr.data.resize(values);
        for (std::uint64_t i = 0; i < values; ++i) arr.data[i] = float(c.number(key + " " + q(name)));
        img.arrays.push_back(std::move(arr));
    }
}

} // namespace

DenseImage parseLegacyVtk(std::string_view s, const std::string& source)
{
    LegacyCursor c{s, 0, source};
    if (s.substr(0, 22).find("# vtk DataFile") != 0)
        inputError(source, "not a legacy VTK file (no '# vtk DataFile' header); expected a .vtk file");
    c.line(); // version
    c.line(); // title
    const std::string mode = upper(c.word());
    if (mode != "ASCII" && mode != "BINARY") inputError(source, "file type '" + mode.substr(0, 20) + "'; expected ASCII or BINARY");
    c.endLine();
    const std::string ds = upper(c.word());
    const std::string kind = upper(c.word());
    if (ds != "DATASET" || kind != "STRUCTURED_POINTS")
        inputError(source, "dataset '" + kind.substr(0, 30) + "' is not supported; expected DATASET STRUCTURED_POINTS");
    DenseImage img;
    img.hasGeometry = true;
    std::array<std::int64_t, 3> pd{0, 0, 0};
    bool haveDims = false, cells = false, haveData = false;
    while (true) {
        const std::string key = upper(c.word());
        if (key.empty()) break;
        if (key == "DIMENSIONS") {
            for (int a = 0; a < 3; ++a) {
                const double v = c.number("DIMENSIONS");
                if (!(v >= 1) || v > 1e12 || v != std::floor(v))
                    inputError(source, "DIMENSIONS value " + std::to_string(v) + " is not a positive integer");
                pd[a] = std::int64_t(v);
            }
            checkDims(pd, source);
            haveDims = true;
        } else if (key == "ORIGIN") {
            for (int a = 0; a < 3; ++a) img.origin[a] = c.number("ORIGIN");
        } else if (key == "SPACING" || key == "ASPECT_RATIO") {
            for (int a = 0; a < 3; ++a) img.spacing[a] = c.number(key);
        } else if (key == "POINT_DATA" || key == "CELL_DATA") {
            if (!haveDims) inputError(source, key + " before DIMENSIONS");
            if (haveData) break; // only the first kind of data
            cells = key == "CELL_DATA";
            haveData = true;
            std::array<std::int64_t, 3> d = pd;
            if (cells)
                for (int a = 0; a < 3; ++a) d[a] = std::max<std::int64_t>(pd[a] - 1, 1);
            img.dims = d;
            const double n = c.number(key);
            if (n != double(img.voxelCount()))
                inputError(source, key + " " + std::to_string(n) + " does not match DIMENSIONS ("
                                       + std::to_string(img.voxelCount()) + " expected; mismatched shape)");
        } else if (key == "VECTORS" || key == "SCALARS" || key == "NORMALS") {
            if (!haveData) inputError(source, key + " before POINT_DATA or CELL_DATA");
            readLegacyArray(c, img, key, mode == "BINARY");
        } else if (key == "FIELD" || key == "LOOKUP_TABLE" || key == "COLOR_SCALARS" || key == "TEXTURE_COORDINATES"
                   || key == "TENSORS") {
            inputError(source, key + " sections are not supported; expected VECTORS and SCALARS");
        } else {
            inputError(source, "unexpected keyword '" + key.substr(0, 30) + "'");
        }
    }
    if (!haveDims) inputError(source, "no DIMENSIONS line");
    if (img.arrays.empty()) inputError(source, "no VECTORS or SCALARS data");
    for (int a = 0; a < 3; ++a) {
        if (!(img.spacing[a] > 0) || !std::isfinite(img.spacing[a]))
            inputError(source, "SPACING on axis " + std::string(1, "xyz"[a]) + " is not positive; expected a voxel size > 0");
        if (cells) img.origin[a] += 0.5 * img.spacing[a];
    }
    return img;
}

} // namespace vdbexport
