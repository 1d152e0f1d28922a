// checkVdbStructure(): the structural check of an untrusted .vdb file (layer 1 of the read
// defences, docs/inputs.md). It follows the byte layout OpenVDB 10 reads (io/Archive.cc,
// io/GridDescriptor.cc, MetaMap::readMeta, math/Maps.h, tree/RootNode.h, InternalNode.h,
// LeafNode*.h readTopology/readBuffers, io/Compression.h readCompressedValues) and checks every
// count and size it meets against the file and against what the node can hold.
#include "vdbexport/io/VdbCheck.h"

#include "Quote.h"

#include <lic/util/Error.h>

#include <openvdb/openvdb.h>
#include <openvdb/io/Compression.h>
#include <openvdb/io/DelayedLoadMetadata.h>
#include <openvdb/io/GridDescriptor.h>

#include <blosc.h>
#include <zlib.h>

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <map>
#include <memory>
#include <set>
#include <vector>

#include <sys/stat.h>
#include <unistd.h>

namespace vdbexport {

namespace {

using detail::q;

/// A refusal by the check: the marker and the rule's name (VdbCheck.h), then the message.
lic::InputError refusal(const char* rule, const std::string& message)
{
    return lic::InputError(std::string(kVdbCheckMarker) + rule + "] " + message);
}

/// The newest VDB file format version read. OpenVDB 13 writes 225 (OPENVDB_FILE_VERSION_HALF_GRID):
/// the bump says a file may hold its new half-precision grid type (`Tree_half_5_4_3`); every
/// other type is laid out as in 224 (OpenVDB 10 to 12: 13 changed only how old versions are
/// read), and OpenVDB 10 reads a newer version number with a warning. So a 225 file of the
/// types below is read by the OpenVDB licvdb is built with; a half grid is refused by name.
constexpr uint32_t kNewestFileVersion = std::max<uint32_t>(225, openvdb::OPENVDB_FILE_VERSION);
constexpr const char* kNewestFileWriter = openvdb::OPENVDB_FILE_VERSION > 225 ? "this build's OpenVDB" : "13.x";

constexpr uint64_t kBloscOverhead = BLOSC_MAX_OVERHEAD; // 16-byte blosc header
constexpr uint64_t kGuardBytes = 4096;                  // checked slack after each decoded block
constexpr int32_t kMaxCoord = 1 << 30;                  // index range licvdb accepts
constexpr uint32_t kMaxStringBytes = 1u << 30;

/// How a leaf of a tree type stores its values (tree/LeafNode.h, LeafNodeBool.h, LeafNodeMask.h).
enum class LeafKind { Plain, Bool, Mask };

/// What the check needs to know about one tree type OpenVDB registers.
struct TreeSpec
{
    std::string valueType;
    uint64_t valueSize = 0; ///< bytes of a value (root background, tiles, inactive values)
    uint64_t halfSize = 0;  ///< bytes of a value stored as half float; 0 if never converted
    bool boolValues = false;
    LeafKind leaf = LeafKind::Plain;
    uint64_t memLeaf = 0, memInternal1 = 0, memInternal2 = 0; ///< bytes in memory per node
};

template<typename TreeT>
TreeSpec makeSpec(LeafKind leaf)
{
    using V = typename TreeT::ValueType;
    using Leaf = typename TreeT::LeafNodeType;
    using Int2 = typename TreeT::RootNodeType::ChildNodeType;
    using Int1 = typename Int2::ChildNodeType;
    static_assert(Leaf::LOG2DIM == 3 && Int1::LOG2DIM == 4 && Int2::LOG2DIM == 5, "5-4-3 trees only");
    TreeSpec s;
    s.valueType = openvdb::typeNameAsString<typename Leaf::BuildType>();
    s.valueSize = sizeof(V);
    if constexpr (openvdb::io::RealToHalf<V>::isReal)
        s.halfSize = sizeof(typename openvdb::io::RealToHalf<V>::HalfT);
    s.boolValues = std::is_same_v<V, bool>;
    s.leaf = leaf;
    s.memLeaf = sizeof(Leaf) + (leaf == LeafKind::Plain ? Leaf::SIZE * sizeof(V) : 0);
    s.memInternal1 = sizeof(Int1);
    s.memInternal2 = sizeof(Int2);
    return s;
}

/// Tree types walked, by grid type name (without the `_HalfFloat` suffix).
const std::map<std::string, TreeSpec>& treeSpecs()
{
    static const std::map<std::string, TreeSpec> specs = [] {
        using namespace openvdb;
        std::map<std::string, TreeSpec> m;
        m[FloatGrid::gridType()] = makeSpec<FloatTree>(LeafKind::Plain);
        m[DoubleGrid::gridType()] = makeSpec<DoubleTree>(LeafKind::Plain);
        m[Int32Grid::gridType()] = makeSpec<Int32Tree>(LeafKind::Plain);
        m[Int64Grid::gridType()] = makeSpec<Int64Tree>(LeafKind::Plain);
        m[Vec3SGrid::gridType()] = makeSpec<Vec3STree>(LeafKind::Plain);
        m[Vec3DGrid::gridType()] = makeSpec<Vec3DTree>(LeafKind::Plain);
        m[Vec3IGrid::gridType()] = makeSpec<Vec3ITree>(LeafKind::Plain);
        m[BoolGrid::gridType()] = makeSpec<BoolTree>(LeafKind::Bool);
        m[MaskGrid::gridType()] = makeSpec<MaskTree>(LeafKind::Mask);
        return m;
    }();
    return specs;
}

/// Byte sizes of the fixed-size metadata types OpenVDB registers (TypedMetadata<T>::readValue
/// reads sizeof(T) whatever size the file states, so the two must agree).
const std::map<std::string, uint32_t>& metadataSizes()
{
    static const std::map<std::string, uint32_t> sizes = [] {
        using namespace openvdb;
        std::map<std::string, uint32_t> m;
        m[typeNameAsString<bool>()] = sizeof(bool);
        m[typeNameAsString<double>()] = sizeof(double);
        m[typeNameAsString<float>()] = sizeof(float);
        m[typeNameAsString<int32_t>()] = sizeof(int32_t);
        m[typeNameAsString<int64_t>()] = sizeof(int64_t);
        m[typeNameAsString<Vec2i>()] = sizeof(Vec2i);
        m[typeNameAsString<Vec2s>()] = sizeof(Vec2s);
        m[typeNameAsString<Vec2d>()] = sizeof(Vec2d);
        m[typeNameAsString<Vec3i>()] = sizeof(Vec3i);
        m[typeNameAsString<Vec3s>()] = sizeof(Vec3s);
        m[typeNameAsString<Vec3d>()] = sizeof(Vec3d);
        m[typeNameAsString<Vec4i>()] = sizeof(Vec4i);
        m[typeNameAsString<Vec4s>()] = sizeof(Vec4s);
        m[typeNameAsString<Vec4d>()] = sizeof(Vec4d);
        m[typeNameAsString<Mat4s>()] = sizeof(Mat4s);
        m[typeNameAsString<Mat4d>()] = sizeof(Mat4d);
        m[typeNameAsString<PointIndex32>()] = sizeof(int32_t);
        m[typeNameAsString<PointIndex64>()] = sizeof(int64_t);
        return m;
    }();
    return sizes;
}

std::string coordString(const openvdb::Coord& c)
{
    return "(" + std::to_string(c[0]) + ", " + std::to_string(c[1]) + ", " + std::to_string(c[2]) + ")";
}

/// The check of one file: a bounds-checked reader plus the context for error messages.
class Checker
{
public:
    Checker(const std::string& path, bool decode) : mPath(path), mDecode(decode)
    {
        mFile = std::fopen(path.c_str(), "rb");
        if (!mFile)
            throw refusal("open", "cannot open " + q(path) + " for reading (" + std::strerror(errno)
                                  + "); expected a readable .vdb file");
        // A buffer of our own: glibc's setvbuf ignores the size when given no buffer and keeps
        // its 4 KiB one, and every read or seek past it is a system call (some 4 300 for a
        // 17 MB file, a few µs each on a virtual machine).
        std::setvbuf(mFile, mBuffer.get(), _IOFBF, kBufferBytes);
        if (fseeko(mFile, 0, SEEK_END) != 0) throw corrupt("not-seekable", "cannot seek in the file");
        const off_t end = ftello(mFile);
        // no-size: unreachable (tests/unit/test_vdbcheck_rules.cpp lists it), ftello does not fail
        // once fseeko to the end has succeeded.
        if (end < 0) throw corrupt("no-size", "cannot tell the file size");
        mSize = uint64_t(end);
        fseeko(mFile, 0, SEEK_SET);
    }
    ~Checker() { std::fclose(mFile); }
    Checker(const Checker&) = delete;
    Checker& operator=(const Checker&) = delete;

    VdbCheckResult run();

private:
    // ---- errors --------------------------------------------------------------------------
    std::string where() const
    {
        std::string s;
        for (const auto& w : mWhere) s += (s.empty() ? "" : ", ") + w;
        return s;
    }
    lic::InputError corrupt(const char* rule, const std::string& what) const
    {
        const std::string w = where();
        return refusal(rule, q(mPath) + " is corrupt: " + (w.empty() ? "" : w + ": ") + what + " (at byte "
                               + std::to_string(mPos) + "); expected an intact OpenVDB .vdb file");
    }
    lic::InputError truncated(const char* rule, const std::string& what) const
    {
        const std::string w = where();
        return refusal(rule, q(mPath) + " is truncated or corrupt: " + (w.empty() ? "" : w + ": ") + what
                               + " (the file has " + std::to_string(mSize)
                               + " bytes); expected an intact OpenVDB .vdb file");
    }
    /// Pushes a context ("grid 'vel'", "leaf at (0, 8, 0)") for the lifetime of the object.
    struct Scope
    {
        Scope(Checker& c, std::string w) : mC(c) { mC.mWhere.push_back(std::move(w)); }
        ~Scope() { mC.mWhere.pop_back(); }
        Checker& mC;
    };

    // ---- bounded reads -------------------------------------------------------------------
    uint64_t left() const { return mSize - mPos; }
    void read(void* dst, uint64_t n, const char* what)
    {
        if (n > left()) throw truncated("cut-short", std::string(what) + " is cut short at byte " + std::to_string(mPos));
        // read-failed: reachable only if the file shrinks (or the disk fails) while it is checked;
        // no file can provoke it.
        if (n > 0 && std::fread(dst, 1, n, mFile) != n) throw truncated("read-failed", std::string("reading ") + what + " failed");
        mPos += n;
    }
    template<typename T> T get(const char* what)
    {
        T v{};
        read(&v, sizeof(T), what);
        return v;
    }
    void skip(uint64_t n, const char* what)
    {
        if (n > left()) throw truncated("skip-cut-short", std::string(what) + " is cut short at byte " + std::to_string(mPos));
        // skip-failed: unreachable, seeking forward within a regular file's size does not fail.
        if (n > 0 && fseeko(mFile, off_t(n), SEEK_CUR) != 0) throw truncated("skip-failed", std::string("seeking over ") + what + " failed");
        mPos += n;
    }
    void seek(uint64_t p)
    {
        // seek: redundant, run() seeks only to a grid's end offset, which it has checked against the
        // file's size (rule grid-end).
        if (p > mSize || fseeko(mFile, off_t(p), SEEK_SET) != 0) throw truncated("seek", "cannot seek to byte " + std::to_string(p));
        mPos = p;
    }
    /// A string as OpenVDB writes one (uint32 length, bytes).
    std::string string(const char* what)
    {
        const uint32_t n = get<uint32_t>(what);
        if (n > left() || n > kMaxStringBytes)
            throw truncated("string-size", std::string(what) + " claims " + std::to_string(n) + " bytes, more than the file has left");
        std::string s(n, '\0');
        read(s.data(), n, what);
        return s;
    }

    // ---- parts -------------------------------------------------------------------------
    void header(VdbCheckResult& r);
    /// What a grid's metadata decides about reading it.
    struct MetaInfo
    {
        int64_t delayedCount = -1; ///< entries of the `__delayedload` table; -1 if absent
        int halfFloat = -1;        ///< `is_saved_as_half_float`: 0, 1, or -1 if absent
    };
    /// MetaMap::readMeta.
    MetaInfo metaMap();
    void metadataValue(const std::string& name, const std::string& type, uint32_t bytes, MetaInfo& info);
    void delayedLoad(uint32_t bytes, int64_t& count);
    void transform(bool nested = false);
    void tree(const TreeSpec& spec, VdbGridCheck& g);
    void internal2(const TreeSpec& spec, const openvdb::Coord& origin, VdbGridCheck& g);
    void internal1(const TreeSpec& spec, const openvdb::Coord& origin, VdbGridCheck& g);
    void leafBuffers(const TreeSpec& spec, VdbGridCheck& g);
    /// io::readCompressedValues for a node of `count` values with value mask `mask` (bit words).
    void values(const TreeSpec& spec, uint64_t count, const uint64_t* mask, const char* what);
    /// One zip or blosc block (or its raw fallback) that must hold exactly `bytes` bytes.
    void block(uint64_t bytes, bool boolValues, const char* what);
    /// `padded`: also accept the 128 bytes OpenVDB's compression::bloscCompress pads small
    /// arrays to (BLOSC_PAD_BYTES; the delayed-load table).
    void bloscBlock(const std::vector<char>& data, uint64_t bytes, bool boolValues, bool padded = false);
    void checkBools(const char* data, uint64_t n);

    std::string mPath;
    static constexpr std::size_t kBufferBytes = std::size_t(1) << 20;
    std::unique_ptr<char[]> mBuffer = std::make_unique_for_overwrite<char[]>(kBufferBytes);
    std::FILE* mFile = nullptr;
    uint64_t mSize = 0, mPos = 0;
    bool mDecode = true; ///< decode compressed blocks (false: their headers and sizes only)
    std::vector<std::string> mWhere;
    uint32_t mVersion = 0;
    uint32_t mCompression = 0; ///< of the grid being walked
    bool mHalf = false;        ///< of the grid being walked
    struct Leaf
    {
        openvdb::Coord origin;
        std::array<uint64_t, 8> mask;
    };
    std::vector<Leaf> mLeaves; ///< of the grid being walked, in file order
    uint64_t mInternal2 = 0;   ///< upper internal nodes of the grid being walked
};

void Checker::header(VdbCheckResult& r)
{
    int64_t magic = 0;
    const int64_t expected = openvdb::OPENVDB_MAGIC;
    if (mSize < sizeof(magic)) {
        std::string head(mSize, '\0');
        read(head.data(), mSize, "header");
        if (!head.empty() && std::memcmp(head.data(), &expected, head.size()) == 0)
            throw truncated("header-short", "its header is cut short");
        throw refusal("not-vdb-short", q(mPath) + " is not an OpenVDB file (no VDB header); expected a .vdb file");
    }
    magic = get<int64_t>("header");
    if (magic != expected)
        throw refusal("not-vdb", q(mPath) + " is not an OpenVDB file (no VDB header); expected a .vdb file");
    if (left() < 4 + 4 + 4 + 1 + 36) throw truncated("header-cut-short", "its header is cut short");
    mVersion = get<uint32_t>("header");
    r.fileVersion = mVersion;
    r.libraryMajor = get<uint32_t>("header");
    r.libraryMinor = get<uint32_t>("header");
    if (mVersion < openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION || mVersion > kNewestFileVersion)
        throw refusal("version", q(mPath) + " has VDB file format version " + std::to_string(mVersion)
                              + " (written by OpenVDB " + std::to_string(r.libraryMajor) + "."
                              + std::to_string(r.libraryMinor) + "); licvdb reads versions "
                              + std::to_string(openvdb::OPENVDB_FILE_VERSION_NODE_MASK_COMPRESSION) + " to "
                              + std::to_string(kNewestFileVersion) + " (OpenVDB 2.0 to " + kNewestFileWriter
                              + "): save it again with such a version, or it is corrupt");
}

void Checker::checkBools(const char* data, uint64_t n)
{
    for (uint64_t i = 0; i < n; ++i)
        if (static_cast<unsigned char>(data[i]) > 1)
            throw corrupt("bool-value", "a bool value is " + std::to_string(static_cast<unsigned char>(data[i])) + ", not 0 or 1");
}

Checker::MetaInfo Checker::metaMap()
{
    const uint32_t count = get<uint32_t>("the metadata count");
    // Each entry takes at least 12 bytes (two string lengths and a size).
    if (uint64_t(count) * 12 > left())
        throw truncated("meta-count", "it claims " + std::to_string(count) + " metadata entries, more than the file can hold");
    MetaInfo info;
    for (uint32_t i = 0; i < count; ++i) {
        const std::string name = string("a metadata name");
        const Scope s(*this, "metadata " + q(name));
        const std::string type = string("a metadata type name");
        const uint32_t bytes = get<uint32_t>("a metadata size");
        if (bytes > left())
            throw truncated("meta-size", "the value claims " + std::to_string(bytes) + " bytes, more than the file has left");
        metadataValue(name, type, bytes, info);
    }
    return info;
}

void Checker::metadataValue(const std::string& name, const std::string& type, uint32_t bytes, MetaInfo& info)
{
    // OpenVDB 10 keeps a grid's half-float flag in this metadata (GridBase::saveFloatAsHalf),
    // and reading the metadata replaces what the grid descriptor said: this value decides.
    const bool halfFlag = name == openvdb::GridBase::META_SAVE_HALF_FLOAT;
    if (halfFlag && type != openvdb::typeNameAsString<bool>())
        throw corrupt("half-flag-type", "the half-float flag is a " + type + ", not a bool");
    if (type == openvdb::io::DelayedLoadMetadata::staticTypeName()) {
        delayedLoad(bytes, info.delayedCount);
        return;
    }
    const auto& sizes = metadataSizes();
    if (const auto it = sizes.find(type); it != sizes.end()) {
        if (bytes != it->second)
            throw corrupt("meta-value-size", "a " + type + " value stores " + std::to_string(bytes) + " bytes; a " + type + " has "
                          + std::to_string(it->second));
        if (type == openvdb::typeNameAsString<bool>()) {
            char b = 0;
            read(&b, 1, "a bool value");
            checkBools(&b, 1);
            if (halfFlag) info.halfFloat = b;
            return;
        }
        skip(bytes, "a metadata value");
        return;
    }
    if (type == openvdb::typeNameAsString<std::string>() || !openvdb::Metadata::isRegisteredType(type)) {
        skip(bytes, "a metadata value"); // strings and unknown types: OpenVDB reads `bytes` bytes
        return;
    }
    // meta-type: unreachable with OpenVDB 10's own registrations (each registered type is in
    // metadataSizes(), a string or the delayed-load table): for types a program registers itself.
    throw corrupt("meta-type", "metadata type " + q(type) + " is not one licvdb can check");
}

/// DelayedLoadMetadata::readValue: count, a blosc block (or raw) of count int8 masks, then a
/// blosc block (or raw, or none) of count int64 sizes, within `bytes`.
void Checker::delayedLoad(uint32_t bytes, int64_t& delayedCount)
{
    if (bytes == 0) return;
    const uint64_t end = mPos + bytes;
    const auto need = [&](uint64_t n, const char* what) {
        if (n > end - mPos) throw corrupt("delayed-overrun", std::string(what) + " runs past the end of the metadata value");
    };
    need(8, "the delayed-load table");
    const uint32_t count = get<uint32_t>("the delayed-load count");
    // One entry per leaf, and every leaf takes at least 129 bytes of the file (two value masks
    // and a compression byte): a larger count cannot be true (and would cost memory to decode).
    if (uint64_t(count) * 129 > mSize)
        throw corrupt("delayed-count", "the delayed-load table lists " + std::to_string(count) + " leaves, more than a file of "
                      + std::to_string(mSize) + " bytes can hold");
    delayedCount = count;
    for (int part = 0; part < 2; ++part) {
        const uint64_t elem = part == 0 ? 1 : 8;
        need(4, "the delayed-load table");
        const uint32_t stored = get<uint32_t>("a delayed-load block size");
        if (part == 1 && stored == std::numeric_limits<uint32_t>::max()) break; // no sizes stored
        const uint64_t expected = uint64_t(count) * elem;
        if (stored == 0) {
            need(expected, "the delayed-load table");
            skip(expected, "the delayed-load table");
            continue;
        }
        need(stored, "a delayed-load blosc block");
        std::vector<char> data(stored);
        read(data.data(), stored, "a delayed-load blosc block");
        bloscBlock(data, expected, false, /*padded=*/true);
    }
    // delayed-end: redundant, need() has kept every read of the table within `end`.
    if (mPos > end) throw corrupt("delayed-end", "the delayed-load table runs past its metadata value");
    skip(end - mPos, "a metadata value");
}

void Checker::transform(bool nested)
{
    const std::string type = string("the transform's map type");
    const Scope s(*this, "transform " + q(type));
    std::vector<double> v;
    const auto doubles = [&](int n) {
        for (int i = 0; i < n; ++i) v.push_back(get<double>("the transform"));
    };
    using namespace openvdb::math;
    if (type == AffineMap::mapType() || type == UnitaryMap::mapType()) {
        doubles(16);
        const double det = v[0] * (v[5] * v[10] - v[6] * v[9]) - v[1] * (v[4] * v[10] - v[6] * v[8])
                         + v[2] * (v[4] * v[9] - v[5] * v[8]);
        if (!(std::abs(det) > 0) || !std::isfinite(det)) throw corrupt("affine-singular", "the matrix is singular or not finite");
    } else if (type == ScaleMap::mapType() || type == UniformScaleMap::mapType()) {
        doubles(15);
        for (int a = 0; a < 3; ++a)
            if (!(v[size_t(a)] != 0)) throw corrupt("scale-zero", "a scale is zero");
    } else if (type == ScaleTranslateMap::mapType() || type == UniformScaleTranslateMap::mapType()) {
        doubles(18);
        for (int a = 3; a < 6; ++a)
            if (!(v[size_t(a)] != 0)) throw corrupt("scale-translate-zero", "a scale is zero");
    } else if (type == TranslationMap::mapType()) {
        doubles(3);
    } else if (type == NonlinearFrustumMap::mapType() && !nested) {
        doubles(8); // bounding box, taper, depth
        transform(/*nested=*/true); // the frustum's linear map
    } else {
        throw corrupt("map-type", "map type " + q(type) + " is not an OpenVDB map");
    }
    for (const double d : v)
        if (!std::isfinite(d)) throw corrupt("map-not-finite", "a value is not finite");
}

void Checker::bloscBlock(const std::vector<char>& data, uint64_t bytes, bool boolValues, bool padded)
{
    const uint64_t n = data.size();
    if (n < kBloscOverhead) throw corrupt("blosc-short", "a blosc block of " + std::to_string(n) + " bytes is shorter than its header");
    const auto u8 = [&](int i) { return static_cast<unsigned char>(data[size_t(i)]); };
    const auto u32 = [&](int i) { return uint32_t(u8(i)) | uint32_t(u8(i + 1)) << 8 | uint32_t(u8(i + 2)) << 16 | uint32_t(u8(i + 3)) << 24; };
    const uint32_t flags = u8(2), typesize = u8(3), nbytes = u32(4), blocksize = u32(8), cbytes = u32(12);
    if (cbytes != n)
        throw corrupt("blosc-cbytes", "a blosc block of " + std::to_string(n) + " bytes says it has " + std::to_string(cbytes));
    constexpr uint64_t kPadBytes = 128; // openvdb::compression::BLOSC_PAD_BYTES
    if (padded && bytes <= kPadBytes && nbytes == kPadBytes) bytes = kPadBytes;
    if (nbytes != bytes)
        throw corrupt("blosc-nbytes", "a blosc block claims " + std::to_string(nbytes) + " bytes where " + std::to_string(bytes)
                      + " are expected");
    if (bytes == 0) return;
    if (typesize == 0 || blocksize == 0 || blocksize > nbytes)
        throw corrupt("blosc-blocksize", "a blosc block has a block size of " + std::to_string(blocksize) + " for "
                      + std::to_string(nbytes) + " bytes");
    if ((flags & BLOSC_MEMCPYED) && n != uint64_t(nbytes) + kBloscOverhead)
        throw corrupt("blosc-memcpyed", "an uncompressed blosc block of " + std::to_string(n) + " bytes claims " + std::to_string(nbytes));
    size_t checkedBytes = 0;
    if (blosc_cbuffer_validate(data.data(), n, &checkedBytes) != 0 || checkedBytes != bytes)
        throw corrupt("blosc-header", "a blosc block has an invalid header");
    if (!mDecode) return;
    // Decode into a buffer with a guard zone behind it: the block must fill exactly `bytes`.
    std::vector<unsigned char> out(bytes + kGuardBytes, 0xA5);
    const int got = blosc_decompress_ctx(data.data(), out.data(), bytes, 1);
    // blosc-overrun is a defence against a decoder bug: blosc 1.21 writes no more than the
    // destination size it is given, so no file reaches it.
    for (uint64_t i = bytes; i < out.size(); ++i)
        if (out[i] != 0xA5) throw corrupt("blosc-overrun", "a blosc block decodes past its end");
    if (got < 0 || uint64_t(got) != bytes)
        throw corrupt("blosc-decode", "a blosc block does not decode to its " + std::to_string(bytes) + " bytes (blosc returned "
                      + std::to_string(got) + ")");
    if (boolValues) checkBools(reinterpret_cast<const char*>(out.data()), bytes);
}

void Checker::block(uint64_t bytes, bool boolValues, const char* what)
{
    using namespace openvdb::io;
    // An uncompressed block: only bool values have bytes worth looking at.
    const auto raw = [&] {
        if (boolValues) {
            std::vector<char> values(bytes);
            read(values.data(), bytes, what);
            checkBools(values.data(), bytes);
        } else {
            skip(bytes, what);
        }
    };
    if (!(mCompression & (COMPRESS_BLOSC | COMPRESS_ZIP))) {
        raw();
        return;
    }
    const bool blosc = mCompression & COMPRESS_BLOSC; // OpenVDB prefers blosc when both are set
    const int64_t stored = get<int64_t>(what);
    if (stored <= 0) { // stored uncompressed
        const uint64_t n = uint64_t(0) - uint64_t(stored);
        if (n != bytes)
            throw corrupt("raw-size", std::string(what) + " stores " + std::to_string(n) + " uncompressed bytes where "
                          + std::to_string(bytes) + " are expected");
        raw();
        return;
    }
    const uint64_t n = uint64_t(stored);
    const uint64_t limit = blosc ? bytes + kBloscOverhead : compressBound(uLong(bytes));
    if (n > limit)
        throw corrupt("block-bound", std::string(what) + " claims a " + std::string(blosc ? "blosc" : "zip") + " block of "
                      + std::to_string(n) + " bytes; " + std::to_string(bytes) + " bytes compress to at most "
                      + std::to_string(limit));
    if (n > left()) throw truncated("block-cut-short", std::string(what) + " is cut short at byte " + std::to_string(mPos));
    std::vector<char> data(n);
    read(data.data(), n, what);
    if (blosc) {
        bloscBlock(data, bytes, boolValues);
        return;
    }
    if (!mDecode) return;
    std::vector<unsigned char> out(bytes + 1);
    uLongf outBytes = uLongf(bytes);
    const int rc = uncompress(out.data(), &outBytes, reinterpret_cast<const Bytef*>(data.data()), uLong(n));
    if (rc != Z_OK || outBytes != bytes)
        throw corrupt("zip-decode", std::string("a zip block does not decode to its ") + std::to_string(bytes) + " bytes");
    if (boolValues) checkBools(reinterpret_cast<const char*>(out.data()), bytes);
}

void Checker::values(const TreeSpec& spec, uint64_t count, const uint64_t* mask, const char* what)
{
    using namespace openvdb::io;
    const int8_t meta = get<int8_t>("a node's compression byte");
    if (meta < NO_MASK_OR_INACTIVE_VALS || meta > NO_MASK_AND_ALL_VALS)
        throw corrupt("mask-byte", std::string(what) + ": compression byte " + std::to_string(meta) + " is not 0 to 6");
    const int inactive = (meta == NO_MASK_AND_ONE_INACTIVE_VAL || meta == MASK_AND_ONE_INACTIVE_VAL) ? 1
                       : meta == MASK_AND_TWO_INACTIVE_VALS ? 2 : 0;
    for (int i = 0; i < inactive; ++i) {
        std::vector<char> v(spec.valueSize);
        read(v.data(), spec.valueSize, "an inactive value");
        if (spec.boolValues) checkBools(v.data(), v.size());
    }
    if (meta == MASK_AND_NO_INACTIVE_VALS || meta == MASK_AND_ONE_INACTIVE_VAL || meta == MASK_AND_TWO_INACTIVE_VALS)
        skip(count / 8, "a selection mask");
    uint64_t stored = count;
    if ((mCompression & COMPRESS_ACTIVE_MASK) && meta != NO_MASK_AND_ALL_VALS) {
        stored = 0;
        for (uint64_t w = 0; w < count / 64; ++w) stored += uint64_t(std::popcount(mask[w]));
    }
    if (mHalf && spec.halfSize > 0) {
        if (stored == 0) return; // HalfReader reads nothing for no values
        block(stored * spec.halfSize, false, what);
    } else {
        block(stored * spec.valueSize, spec.boolValues, what);
    }
}

void Checker::internal1(const TreeSpec& spec, const openvdb::Coord& origin, VdbGridCheck& g)
{
    const Scope s(*this, "node at " + coordString(origin));
    ++g.internalNodes;
    std::array<uint64_t, 64> childMask{}, valueMask{};
    read(childMask.data(), sizeof(childMask), "a child mask");
    read(valueMask.data(), sizeof(valueMask), "a value mask");
    for (size_t w = 0; w < childMask.size(); ++w)
        if (childMask[w] & valueMask[w]) throw corrupt("node1-child-and-value", "a slot is marked both child and active value");
    values(spec, 4096, valueMask.data(), "the node's values");
    for (uint32_t i = 0; i < 4096; ++i) {
        if (!(childMask[i >> 6] >> (i & 63) & 1)) continue;
        const openvdb::Coord o = origin + openvdb::Coord(int(i >> 8) * 8, int((i >> 4) & 15) * 8, int(i & 15) * 8);
        Leaf leaf{o, {}};
        if (left() < sizeof(leaf.mask)) {
            const Scope l(*this, "leaf at " + coordString(o));
            throw truncated("leaf-mask-cut-short", "its value mask is cut short at byte " + std::to_string(mPos));
        }
        read(leaf.mask.data(), sizeof(leaf.mask), "a leaf mask");
        mLeaves.push_back(leaf);
    }
}

void Checker::internal2(const TreeSpec& spec, const openvdb::Coord& origin, VdbGridCheck& g)
{
    const Scope s(*this, "node at " + coordString(origin));
    ++g.internalNodes;
    ++mInternal2;
    std::vector<uint64_t> childMask(512), valueMask(512);
    read(childMask.data(), 4096, "a child mask");
    read(valueMask.data(), 4096, "a value mask");
    for (size_t w = 0; w < childMask.size(); ++w)
        if (childMask[w] & valueMask[w]) throw corrupt("node2-child-and-value", "a slot is marked both child and active value");
    values(spec, 32768, valueMask.data(), "the node's values");
    for (uint32_t i = 0; i < 32768; ++i) {
        if (!(childMask[i >> 6] >> (i & 63) & 1)) continue;
        internal1(spec, origin + openvdb::Coord(int(i >> 10) * 128, int((i >> 5) & 31) * 128, int(i & 31) * 128), g);
    }
}

void Checker::tree(const TreeSpec& spec, VdbGridCheck& g)
{
    mLeaves.clear();
    mInternal2 = 0;
    {
        const Scope s(*this, "tree");
        const int32_t buffers = get<int32_t>("the buffer count");
        if (buffers != 1) throw corrupt("buffer-count", "buffer count is " + std::to_string(buffers) + ", not 1");
        std::vector<char> bg(spec.valueSize);
        read(bg.data(), spec.valueSize, "the background value");
        if (spec.boolValues) checkBools(bg.data(), bg.size());
        const uint32_t numTiles = get<uint32_t>("the tile count");
        const uint32_t numChildren = get<uint32_t>("the child count");
        const uint64_t tileBytes = 12 + spec.valueSize + 1;
        if (uint64_t(numTiles) * tileBytes + uint64_t(numChildren) * (12 + 8192) > left())
            throw truncated("root-counts", "its root claims " + std::to_string(numTiles) + " tiles and " + std::to_string(numChildren)
                            + " children, more than the file can hold");
        std::set<openvdb::Coord> origins;
        const auto origin = [&](const char* what) {
            int32_t v[3];
            read(v, sizeof(v), what);
            const openvdb::Coord c(v[0], v[1], v[2]);
            for (int a = 0; a < 3; ++a) {
                if (v[a] % 4096 != 0) throw corrupt("root-origin-align", std::string(what) + " " + coordString(c) + " is not a multiple of 4096");
                if (v[a] < -kMaxCoord || v[a] > kMaxCoord)
                    throw corrupt("root-origin-range", std::string(what) + " " + coordString(c) + " lies outside the index range licvdb reads (±2^30)");
            }
            if (!origins.insert(c).second) throw corrupt("root-origin-twice", std::string(what) + " " + coordString(c) + " appears twice");
            return c;
        };
        std::vector<char> value(spec.valueSize);
        for (uint32_t t = 0; t < numTiles; ++t) {
            origin("a root tile");
            read(value.data(), value.size(), "a tile value");
            if (spec.boolValues) checkBools(value.data(), value.size());
            char active = 0;
            read(&active, 1, "a tile's active flag");
            checkBools(&active, 1);
            ++g.tiles;
        }
        for (uint32_t c = 0; c < numChildren; ++c) internal2(spec, origin("a root child"), g);
    }
    g.leaves = mLeaves.size();
}

void Checker::leafBuffers(const TreeSpec& spec, VdbGridCheck& g)
{
    for (const Leaf& leaf : mLeaves) {
        const Scope s(*this, "leaf at " + coordString(leaf.origin));
        std::array<uint64_t, 8> mask{};
        read(mask.data(), sizeof(mask), spec.leaf == LeafKind::Mask ? "a leaf's values" : "a leaf's value mask");
        if (mask != leaf.mask) throw corrupt("leaf-mask-differs", "the leaf's value mask differs from the one in the tree's topology");
        for (const uint64_t w : mask) g.leafVoxelsOn += uint64_t(std::popcount(w));
        if (spec.leaf == LeafKind::Plain) {
            values(spec, 512, mask.data(), "the leaf's values");
            continue;
        }
        int32_t o[3];
        read(o, sizeof(o), "a leaf origin");
        if (openvdb::Coord(o[0], o[1], o[2]) != leaf.origin)
            throw corrupt("leaf-origin", "the leaf says its origin is " + coordString(openvdb::Coord(o[0], o[1], o[2])));
        if (spec.leaf == LeafKind::Bool) skip(64, "a leaf's values");
    }
}

VdbCheckResult Checker::run()
{
    VdbCheckResult r;
    r.fileBytes = mSize;
    header(r);
    const bool hasOffsets = get<char>("the header") != 0;
    skip(36, "the header's UUID");
    {
        const Scope s(*this, "file metadata");
        (void)metaMap();
    }
    const int32_t gridCount = get<int32_t>("the grid count");
    if (gridCount < 0) throw corrupt("grid-count-negative", "the grid count is " + std::to_string(gridCount));
    if (uint64_t(gridCount) * 12 > left())
        throw truncated("grid-count", "it claims " + std::to_string(gridCount) + " grids, more than the file can hold");
    const auto& specs = treeSpecs();
    std::map<std::string, size_t> byUniqueName;
    for (int32_t i = 0; i < gridCount; ++i) {
        const Scope gs(*this, "grid #" + std::to_string(i + 1));
        VdbGridCheck g;
        const std::string uniqueName = string("the grid name");
        g.name = openvdb::io::GridDescriptor::nameAsString(uniqueName);
        const Scope ns(*this, "grid " + q(g.name));
        g.gridType = string("the grid type");
        const std::string halfSuffix = "_HalfFloat"; // GridDescriptor.cc HALF_FLOAT_TYPENAME_SUFFIX
        if (g.gridType.size() > halfSuffix.size() && g.gridType.ends_with(halfSuffix)) {
            g.halfFloat = true;
            g.gridType.resize(g.gridType.size() - halfSuffix.size());
        }
        g.instanceParent = string("the instance parent name");
        g.instance = !g.instanceParent.empty();
        const int64_t gridPos = get<int64_t>("the grid offsets");
        const int64_t blockPos = get<int64_t>("the grid offsets");
        const int64_t endPos = get<int64_t>("the grid offsets");
        if (!byUniqueName.emplace(uniqueName, r.grids.size()).second) throw corrupt("grid-name-twice", "the grid name appears twice");
        if (g.gridType.starts_with("Tree_half_"))
            throw refusal("half-grid", "grid " + q(g.name) + " is a half-precision grid (" + g.gridType
                                       + ", OpenVDB 13's HalfGrid), which licvdb does not read: save it as a float grid "
                                       "(half-float storage, saveFloatAsHalf, is fine)");
        if (!openvdb::GridBase::isRegistered(g.gridType))
            throw corrupt("grid-type", "grid type " + q(g.gridType) + " is not an OpenVDB grid type");
        const auto spec = specs.find(g.gridType);
        if (g.instance) {
            const auto parent = byUniqueName.find(g.instanceParent);
            if (parent == byUniqueName.end() || r.grids[parent->second].instance
                || r.grids[parent->second].gridType != g.gridType)
                throw corrupt("instance-parent", "its instance parent " + q(openvdb::io::GridDescriptor::nameAsString(g.instanceParent))
                              + " is not an earlier grid of the same type");
        }
        if (hasOffsets) {
            if (endPos > int64_t(mSize))
                throw truncated("grid-end", "grid " + q(g.name) + " should end at byte " + std::to_string(endPos));
            // An instance has no tree: OpenVDB leaves its block offset 0.
            if (gridPos != int64_t(mPos) || endPos < gridPos || (!g.instance && (blockPos < gridPos || endPos < blockPos)))
                throw truncated("grid-offsets", "grid " + q(g.name) + " has inconsistent offsets");
        }
        g.compression = get<uint32_t>("the grid's compression flags");
        using namespace openvdb::io;
        if (g.compression & ~uint32_t(COMPRESS_ZIP | COMPRESS_ACTIVE_MASK | COMPRESS_BLOSC))
            throw corrupt("compression-flags", "compression flags " + std::to_string(g.compression) + " are not OpenVDB's");
        mCompression = g.compression;
        MetaInfo meta;
        {
            const Scope s(*this, "metadata");
            meta = metaMap();
        }
        const int64_t delayedCount = meta.delayedCount;
        // What OpenVDB 10 will use: the metadata flag, false without one (the descriptor's
        // `_HalfFloat` suffix is overwritten when the grid's metadata is read).
        g.halfFloat = meta.halfFloat == 1;
        mHalf = g.halfFloat;
        transform();
        if (g.instance) {
            if (hasOffsets && int64_t(mPos) != endPos)
                throw corrupt("instance-end", "the instance's offsets do not match its contents");
            r.grids.push_back(std::move(g));
            continue;
        }
        if (spec == specs.end()) {
            g.skipReason = g.gridType.find("ptdataidx") != std::string::npos || g.gridType.find("ptidx") != std::string::npos
                               ? "point grids are not read by licvdb"
                               : "grid type " + g.gridType + " is not read by licvdb";
            if (!hasOffsets)
                throw refusal("streamed-unsupported", q(mPath) + " has grid " + q(g.name) + " of type " + g.gridType
                                      + " in a streamed file (no grid offsets), which licvdb cannot skip: "
                                      + g.skipReason);
            seek(uint64_t(endPos));
            r.grids.push_back(std::move(g));
            continue;
        }
        g.valueType = spec->second.valueType;
        tree(spec->second, g);
        if (hasOffsets && int64_t(mPos) != blockPos)
            throw corrupt("topology-end", "the tree's topology ends at byte " + std::to_string(mPos) + ", its offsets say "
                          + std::to_string(blockPos));
        leafBuffers(spec->second, g);
        if (hasOffsets && int64_t(mPos) != endPos)
            throw corrupt("data-end", "the grid's data ends at byte " + std::to_string(mPos) + ", its offsets say " + std::to_string(endPos));
        if (delayedCount >= 0 && uint64_t(delayedCount) != g.leaves)
            throw corrupt("delayed-leaves", "its delayed-load table lists " + std::to_string(delayedCount) + " leaves; the tree has "
                          + std::to_string(g.leaves));
        const TreeSpec& ts = spec->second;
        r.memoryBytes += g.leaves * ts.memLeaf + (g.internalNodes - mInternal2) * ts.memInternal1
                       + mInternal2 * ts.memInternal2;
        r.grids.push_back(std::move(g));
    }
    return r;
}

} // namespace

std::string vdbCheckRule(const std::string& message)
{
    const auto at = message.find(kVdbCheckMarker);
    if (at == std::string::npos) return "";
    const auto from = at + kVdbCheckMarker.size(), to = message.find(']', from);
    return to == std::string::npos ? "" : message.substr(from, to - from);
}

uint64_t readMemoryLimitBytes()
{
    if (const char* env = std::getenv("LICVDB_READ_MEMORY_MB")) {
        char* end = nullptr;
        const double mb = std::strtod(env, &end);
        if (end != env && mb > 0) return uint64_t(mb * 1048576.0);
    }
    const long pages = ::sysconf(_SC_PHYS_PAGES), pageSize = ::sysconf(_SC_PAGESIZE);
    return pages > 0 && pageSize > 0 ? uint64_t(0.8 * double(pages) * double(pageSize)) : 0;
}

VdbCheckResult checkVdbStructure(const std::string& path, VdbCheckDepth depth)
{
    openvdb::initialize();
    struct stat st{};
    if (path.empty()) throw refusal("no-path", "no .vdb file given; expected a path to a .vdb file");
    if (::stat(path.c_str(), &st) != 0)
        throw refusal("not-found", "file " + q(path) + " not found; expected a .vdb file");
    if (S_ISDIR(st.st_mode)) throw refusal("directory", q(path) + " is a directory; expected a .vdb file");
    if (S_ISREG(st.st_mode) && st.st_size == 0)
        throw refusal("empty", "file " + q(path) + " is empty (0 bytes); expected a .vdb file");
    Checker checker(path, depth == VdbCheckDepth::Full);
    VdbCheckResult r = checker.run();
    if (depth == VdbCheckDepth::Layout) return r; // a file this process wrote from what it held
    const uint64_t limit = readMemoryLimitBytes();
    if (limit > 0 && r.memoryBytes > limit)
        throw refusal("memory", q(path) + " would need about " + std::to_string(r.memoryBytes >> 20)
                                    + " MiB of memory to read, more than the " + std::to_string(limit >> 20)
                                    + " MiB allowed (80 % of this machine's memory, or LICVDB_READ_MEMORY_MB)"
                                      "; refused as too large or corrupt");
    return r;
}

} // namespace vdbexport
