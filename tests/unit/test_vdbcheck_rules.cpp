// One directed corrupt file per refusal rule of the structural check (vdbexport/io/VdbCheck.h,
// layer 1 of docs/inputs.md): each starts from a sample of tests/unit/VdbSamples.h, changes the
// bytes at the place the rule guards, and asserts that checkVdbStructure and every read path refuse
// it with that rule's marker (`[vdb-check RULE] `, so: by the check, not by OpenVDB) and its own
// message. A last test reads the rule names out of VdbCheck.cpp, so that a rule added without a
// test here (or a note why it cannot be reached) fails.
#include <gtest/gtest.h>

#include "TempDirSuite.h"
#include "VdbMutants.h"
#include "VdbSamples.h"

#include "vdbexport/io/Info.h"
#include "vdbexport/io/VdbCheck.h"
#include "vdbexport/io/ReadCheck.h"

#include <lic/util/Error.h>

#include <openvdb/io/Compression.h>
#include <openvdb/tools/PointIndexGrid.h>

#include <atomic>
#include <bit>
#include <chrono>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <regex>
#include <set>
#include <thread>

#include <fcntl.h>
#include <sys/socket.h>
#include <sys/stat.h>
#include <sys/un.h>
#include <unistd.h>

namespace fs = std::filesystem;

namespace {

// ---- bytes ------------------------------------------------------------------------------------

using vdb_mutants::inputErrorOf;
using vdb_mutants::readFile;
using vdb_mutants::writeFile;

template<typename T>
T peek(const std::string& bytes, std::size_t at)
{
    T v{};
    std::memcpy(&v, bytes.data() + at, sizeof(T));
    return v;
}

template<typename T>
void poke(std::string& bytes, std::size_t at, T v)
{
    std::memcpy(bytes.data() + at, &v, sizeof(T));
}

// ---- where the parts of a sample lie ----------------------------------------------------------

/// What the layout walk needs to know of a tree type.
struct ValueSpec
{
    std::size_t size = 0, halfSize = 0;
    enum { Plain, Bool, Mask } leaf = Plain;
};

const std::map<std::string, ValueSpec>& valueSpecs()
{
    using namespace openvdb;
    static const std::map<std::string, ValueSpec> specs{
        {FloatGrid::gridType(), {4, 2}},         {DoubleGrid::gridType(), {8, 2}},
        {Int32Grid::gridType(), {4, 0}},         {Int64Grid::gridType(), {8, 0}},
        {Vec3SGrid::gridType(), {12, 6}},        {Vec3DGrid::gridType(), {24, 6}},
        {Vec3IGrid::gridType(), {12, 0}},        {BoolGrid::gridType(), {1, 0, ValueSpec::Bool}},
        {MaskGrid::gridType(), {1, 0, ValueSpec::Mask}},
    };
    return specs;
}

/// A value block of a node (io::writeCompressedValues): where its compression byte and its data
/// (the int64 length word of a zip or blosc block, or the raw values) are, and how many bytes it
/// decodes to.
struct ValueBlock
{
    std::size_t compressionByte = 0, data = 0;
    uint64_t bytes = 0;
};

/// Byte offsets of one grid's parts (the offset of a string is that of its length word).
struct GridLayout
{
    std::string name, type;
    std::size_t nameAt = 0, typeAt = 0, parent = 0, offsets = 0, compression = 0, transform = 0;
    int64_t gridPos = 0, blockPos = 0, endPos = 0;
    std::map<std::string, std::size_t> metaSize; ///< metadata name → its size word (type name before it)
    std::map<std::string, std::string> metaType;
    std::size_t tree = 0;     ///< the buffer count; 0 for an instance
    std::vector<std::size_t> tiles, children; ///< root tiles and children: their origins
    std::vector<std::size_t> node2, node1;    ///< internal nodes: their child masks
    std::vector<ValueBlock> node2Values;
    std::vector<std::size_t> leafTopology;    ///< each leaf's value mask in the topology
    std::vector<std::size_t> leafBuffers;     ///< each leaf's value mask before its values
    std::vector<ValueBlock> leafValues;       ///< plain leaves' value blocks
    std::size_t end = 0;                      ///< where the walk ended
};

struct FileLayout
{
    std::size_t gridCount = 0;
    std::vector<GridLayout> grids;
    const GridLayout& grid(const std::string& name) const
    {
        for (const auto& g : grids)
            if (g.name == name) return g;
        throw std::runtime_error("no grid " + name);
    }
};

/// Walks an intact .vdb file as OpenVDB 10 writes it (io/Archive.cc, GridDescriptor, MetaMap,
/// math/Maps.h, RootNode/InternalNode/LeafNode readTopology and readBuffers,
/// io::writeCompressedValues) and records where things are. No checks: intact samples only
/// (LayoutOfEverySampleEndsWhereItsOffsetsSay checks the walk against the files' own offsets).
class LayoutWalk
{
public:
    explicit LayoutWalk(const std::string& bytes) : mB(bytes) {}

    FileLayout run()
    {
        FileLayout f;
        mAt = 20;
        const bool hasOffsets = take<char>() != 0;
        mAt += 36;
        GridLayout fileMeta;
        metadata(fileMeta);
        f.gridCount = mAt;
        const int32_t count = take<int32_t>();
        for (int32_t i = 0; i < count; ++i) {
            GridLayout g;
            g.nameAt = mAt;
            g.name = openvdb::io::GridDescriptor::nameAsString(string());
            g.typeAt = mAt;
            g.type = string();
            if (g.type.ends_with("_HalfFloat")) g.type.resize(g.type.size() - 10);
            g.parent = mAt;
            const bool instance = !string().empty();
            g.offsets = mAt;
            g.gridPos = take<int64_t>();
            g.blockPos = take<int64_t>();
            g.endPos = take<int64_t>();
            g.compression = mAt;
            mCompression = take<uint32_t>();
            metadata(g);
            mHalf = g.metaSize.count("is_saved_as_half_float") && mB[g.metaSize.at("is_saved_as_half_float") + 4] == 1;
            g.transform = mAt;
            transform();
            if (!instance) tree(valueSpecs().at(g.type), g);
            g.end = mAt;
            if (hasOffsets) mAt = std::size_t(g.endPos);
            f.grids.push_back(std::move(g));
        }
        return f;
    }

private:
    template<typename T>
    T take()
    {
        const T v = peek<T>(mB, mAt);
        mAt += sizeof(T);
        return v;
    }
    std::string string()
    {
        const auto n = take<uint32_t>();
        mAt += n;
        return mB.substr(mAt - n, n);
    }
    void metadata(GridLayout& g)
    {
        const auto count = take<uint32_t>();
        for (uint32_t i = 0; i < count; ++i) {
            const std::string name = string(), type = string();
            g.metaType[name] = type;
            g.metaSize[name] = mAt;
            mAt += take<uint32_t>();
        }
    }
    void transform()
    {
        using namespace openvdb::math;
        static const std::map<std::string, int> doubles{
            {AffineMap::mapType(), 16},      {UnitaryMap::mapType(), 16},         {ScaleMap::mapType(), 15},
            {UniformScaleMap::mapType(), 15}, {ScaleTranslateMap::mapType(), 18}, {UniformScaleTranslateMap::mapType(), 18},
            {TranslationMap::mapType(), 3},   {NonlinearFrustumMap::mapType(), 8}};
        const std::string type = string();
        mAt += 8 * std::size_t(doubles.at(type));
        if (type == NonlinearFrustumMap::mapType()) transform(); // the frustum's linear map
    }
    /// io::readCompressedValues for `count` values under `mask` (count/64 words).
    ValueBlock values(const ValueSpec& s, uint64_t count, const std::vector<uint64_t>& mask)
    {
        using namespace openvdb::io;
        ValueBlock b;
        b.compressionByte = mAt;
        const auto meta = take<int8_t>();
        mAt += s.size * (meta == NO_MASK_AND_ONE_INACTIVE_VAL || meta == MASK_AND_ONE_INACTIVE_VAL ? 1
                         : meta == MASK_AND_TWO_INACTIVE_VALS                                  ? 2
                                                                                              : 0);
        if (meta == MASK_AND_NO_INACTIVE_VALS || meta == MASK_AND_ONE_INACTIVE_VAL || meta == MASK_AND_TWO_INACTIVE_VALS)
            mAt += count / 8;
        uint64_t stored = count;
        if ((mCompression & COMPRESS_ACTIVE_MASK) && meta != NO_MASK_AND_ALL_VALS) {
            stored = 0;
            for (const uint64_t w : mask) stored += uint64_t(std::popcount(w));
        }
        const bool half = mHalf && s.halfSize > 0;
        b.bytes = stored * (half ? s.halfSize : s.size);
        b.data = mAt;
        if (half && stored == 0) return b;
        if (mCompression & (COMPRESS_BLOSC | COMPRESS_ZIP)) {
            const auto n = take<int64_t>();
            mAt += std::size_t(n > 0 ? n : -n);
        } else {
            mAt += b.bytes;
        }
        return b;
    }
    std::vector<uint64_t> masks(std::size_t words)
    {
        std::vector<uint64_t> m(words);
        std::memcpy(m.data(), mB.data() + mAt, words * 8);
        mAt += words * 8;
        return m;
    }
    void tree(const ValueSpec& s, GridLayout& g)
    {
        g.tree = mAt;
        mAt += 4 + s.size;
        const auto tiles = take<uint32_t>(), children = take<uint32_t>();
        for (uint32_t t = 0; t < tiles; ++t) {
            g.tiles.push_back(mAt);
            mAt += 12 + s.size + 1;
        }
        std::vector<std::vector<uint64_t>> leafMasks;
        for (uint32_t c = 0; c < children; ++c) {
            g.children.push_back(mAt);
            mAt += 12;
            g.node2.push_back(mAt);
            const auto child2 = masks(512), value2 = masks(512);
            g.node2Values.push_back(values(s, 32768, value2));
            for (uint32_t i = 0; i < 32768; ++i) {
                if (!(child2[i >> 6] >> (i & 63) & 1)) continue;
                g.node1.push_back(mAt);
                const auto child1 = masks(64), value1 = masks(64);
                values(s, 4096, value1);
                for (uint32_t j = 0; j < 4096; ++j) {
                    if (!(child1[j >> 6] >> (j & 63) & 1)) continue;
                    g.leafTopology.push_back(mAt);
                    leafMasks.push_back(masks(8));
                }
            }
        }
        if (g.blockPos > 0) mAt = std::size_t(g.blockPos);
        for (const auto& m : leafMasks) {
            g.leafBuffers.push_back(mAt);
            mAt += 64;
            if (s.leaf == ValueSpec::Plain) g.leafValues.push_back(values(s, 512, m));
            else mAt += 12 + (s.leaf == ValueSpec::Bool ? 64 : 0);
        }
    }

    const std::string& mB;
    std::size_t mAt = 0;
    uint32_t mCompression = 0;
    bool mHalf = false;
};

FileLayout layoutOf(const std::string& bytes) { return LayoutWalk(bytes).run(); }

// ---- the assertion ----------------------------------------------------------------------------

/// The message begins with the layer-1 marker and `rule`, and holds `fragment`.
void expectRefusal(const std::string& msg, const std::string& rule, const std::string& fragment)
{
    EXPECT_EQ(msg.rfind(std::string(vdbexport::kVdbCheckMarker) + rule + "] ", 0), 0u)
        << "expected a refusal by rule " << rule << ", got: " << msg;
    EXPECT_EQ(vdbexport::vdbCheckRule(msg), rule) << msg;
    EXPECT_NE(msg.find(fragment), std::string::npos) << "expected \"" << fragment << "\" in: " << msg;
}

/// checkVdbStructure refuses `path` by `rule` with `fragment` in its message, and so does the
/// read path of every command (describeVdb: checkedVdb, then OpenVDB), with the same message.
void expectRefusedBy(const std::string& path, const std::string& rule, const std::string& fragment)
{
    const std::string msg = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    expectRefusal(msg, rule, fragment);
    vdbexport::detail::clearCheckedVdbCache();
    EXPECT_EQ(inputErrorOf([&] { (void)vdbexport::describeVdb(path); }), msg);
}

class VdbCheckRulesTest : public lictest::TempDirSuite<VdbCheckRulesTest>
{
protected:
    static void SetUpTestSuite()
    {
        makeSuiteDir("test_vdbcheck_rules", "samples");
        vdb_samples::writeVdbSamples(sDir / "samples");
    }
    static std::string sample(const std::string& name) { return readFile(sDir / "samples" / name); }
    /// A file of this test's own in the suite's directory.
    static fs::path file(const std::string& name)
    {
        return sDir / (std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()) + "_" + name);
    }
};

// ---- the rules --------------------------------------------------------------------------------

constexpr const char* kField = "field_abc_blosc.vdb";       // one vec3s grid 'velocity', blosc + active mask
constexpr const char* kBake = "bake_like.vdb";              // recipe, int32, bool, float metadata
constexpr const char* kManta = "mantaflow_half_blosc.vdb";  // half floats, uniform-scale maps
constexpr const char* kSplit = "houdini_split_zip.vdb";     // vel.x/.y/.z, zip + active mask
constexpr const char* kAllBlosc = "all_types_blosc.vdb";    // every type, tiles, an instance, a frustum
constexpr const char* kAllNone = "all_types_none.vdb";      // the same uncompressed, no mask compression
constexpr const char* kStreamed = "streamed.vdb";           // io::Stream: no grid offsets

/// One rule: which sample, how to break it at the place the rule guards, the rule's own words.
struct RuleCase
{
    const char* rule;
    const char* sample;
    std::function<void(std::string& bytes, const FileLayout& l)> edit;
    std::string fragment;
};

/// The blosc header of the first full vec3s leaf (512 × 12 bytes) of the field sample.
std::size_t fullLeafBlosc(const std::string& bytes)
{
    const std::size_t at = vdb_mutants::findBloscHeader(bytes, 6144);
    if (at == std::string::npos) throw std::runtime_error("no full vec3s leaf block in the sample");
    return at;
}

/// The field sample's one grid.
const GridLayout& velocity(const FileLayout& l) { return l.grid("velocity"); }

/// The offset of the first value of metadata entry `name` of `g` (after its size word).
std::size_t metaValue(const GridLayout& g, const std::string& name) { return g.metaSize.at(name) + 4; }

/// The metadata entry of `g` of the delayed-load type (OpenVDB names it `file_delayed_load`).
std::size_t delayedTable(const GridLayout& g)
{
    for (const auto& [name, type] : g.metaType)
        if (type == openvdb::io::DelayedLoadMetadata::staticTypeName()) return g.metaSize.at(name);
    throw std::runtime_error("no delayed-load table in grid " + g.name);
}

/// Sets the value mask word of an internal node (child mask at `node`, `words` words each) over
/// its first child: that slot is then both child and active value.
void markChildActive(std::string& bytes, std::size_t node, std::size_t words)
{
    for (std::size_t w = 0; w < words; ++w) {
        const auto child = peek<uint64_t>(bytes, node + 8 * w);
        if (child == 0) continue;
        poke(bytes, node + 8 * (words + w), peek<uint64_t>(bytes, node + 8 * (words + w)) | (child & -child));
        return;
    }
    throw std::runtime_error("the node has no child");
}

std::vector<RuleCase> ruleCases()
{
    return {
        // -- header ---------------------------------------------------------------------------
        {"header-short", kField, [](std::string& b, const FileLayout&) { b.resize(5); }, "its header is cut short"},
        {"not-vdb-short", kField, [](std::string& b, const FileLayout&) { b = "abc"; }, "is not an OpenVDB file"},
        {"not-vdb", kField, [](std::string& b, const FileLayout&) { b[0] = char(b[0] ^ 0x40); },
         "is not an OpenVDB file (no VDB header)"},
        {"header-cut-short", kField, [](std::string& b, const FileLayout&) { b.resize(30); }, "its header is cut short"},
        {"version", kField, [](std::string& b, const FileLayout&) { poke<uint32_t>(b, 8, 226); },
         "has VDB file format version 226"},
        // -- bounded reads ----------------------------------------------------------------------
        {"cut-short", kField, [](std::string& b, const FileLayout&) { b.resize(59); },
         "file metadata: the metadata count is cut short at byte 57"},
        {"skip-cut-short", kStreamed,
         [](std::string& b, const FileLayout& l) { // the last leaf's blosc block said to be raw
             const ValueBlock& v = velocity(l).leafValues.back();
             const auto n = peek<int64_t>(b, v.data);
             if (!(n > 0 && uint64_t(n) < v.bytes)) throw std::runtime_error("the last leaf is not compressed");
             poke<int64_t>(b, v.data, -int64_t(v.bytes));
         },
         "the leaf's values is cut short at byte"},
        {"string-size", kField, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, velocity(l).nameAt, 0x7FFFFFF0u); },
         "the grid name claims 2147483632 bytes, more than the file has left"},
        // -- values that must be bools ------------------------------------------------------------
        {"bool-value", kBake, [](std::string& b, const FileLayout& l) { b[metaValue(l.grid("density"), "lic_cyclic")] = 2; },
         "metadata 'lic_cyclic': a bool value is 2, not 0 or 1"},
        {"bool-value", kAllNone, [](std::string& b, const FileLayout& l) { b[l.grid("float_tiles").tiles.at(0) + 12 + 4] = 2; },
         "grid 'float_tiles', tree: a bool value is 2, not 0 or 1"},
        {"bool-value", kAllNone, [](std::string& b, const FileLayout& l) { b[l.grid("bool").tree + 4] = 3; },
         "grid 'bool', tree: a bool value is 3, not 0 or 1"},
        {"bool-value", kAllNone, [](std::string& b, const FileLayout& l) { b[l.grid("bool").node2Values.at(0).data] = 7; },
         "grid 'bool', tree, node at (0, 0, 0): a bool value is 7, not 0 or 1"},
        // -- metadata ---------------------------------------------------------------------------
        {"meta-count", kField, [](std::string& b, const FileLayout&) { poke<uint32_t>(b, 57, 0xFFFFFFFFu); },
         "it claims 4294967295 metadata entries, more than the file can hold"},
        {"meta-size", kBake, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, l.grid("density").metaSize.at("lic_frames"), 0x7FFFFFF0u); },
         "metadata 'lic_frames': the value claims 2147483632 bytes, more than the file has left"},
        {"half-flag-type", kManta,
         [](std::string& b, const FileLayout& l) { // the type name "bool" before the size word
             const std::size_t size = l.grid("density").metaSize.at("is_saved_as_half_float");
             if (b.substr(size - 4, 4) != "bool") throw std::runtime_error("the half-float flag is not a bool");
             b.replace(size - 4, 4, "bogo");
         },
         "the half-float flag is a bogo, not a bool"},
        {"meta-value-size", kBake, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, l.grid("density").metaSize.at("lic_frames"), 8); },
         "a int32 value stores 8 bytes; a int32 has 4"},
        // -- the delayed-load table (its own blosc blocks: the blosc rules below) ------------------
        {"delayed-overrun", kField, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, delayedTable(velocity(l)), 5); },
         "the delayed-load table runs past the end of the metadata value"},
        {"delayed-count", kField, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, delayedTable(velocity(l)) + 4, 0x7FFFFFFFu); },
         "the delayed-load table lists 2147483647 leaves, more than a file of"},
        {"delayed-leaves", kField,
         [](std::string& b, const FileLayout& l) {
             // One leaf fewer, consistently: the count, the raw mask array one byte shorter, and a
             // byte of slack at the value's end (its size and every offset stay as they are).
             const std::size_t count = delayedTable(velocity(l)) + 4;
             const uint32_t n = peek<uint32_t>(b, count);
             if (peek<uint32_t>(b, count + 4) != 0) throw std::runtime_error("the masks are not stored raw");
             poke<uint32_t>(b, count, n - 1);
             b.erase(count + 8 + (n - 1), 1);
             const std::size_t sizes = count + 8 + (n - 1);
             const uint32_t stored = peek<uint32_t>(b, sizes);
             const std::size_t after = sizes + 4 + (stored == 0xFFFFFFFFu ? 0 : stored == 0 ? 8 * (n - 1) : stored);
             b.insert(after, 1, '\0');
         },
         "its delayed-load table lists 7 leaves; the tree has 8"},
        // -- transforms -------------------------------------------------------------------------
        {"affine-singular", kAllBlosc,
         [](std::string& b, const FileLayout& l) { // the frustum's linear map: a zero matrix
             const std::size_t frustum = l.grid("frustum").transform;
             const std::size_t nested = frustum + 4 + peek<uint32_t>(b, frustum) + 8 * 8;
             if (b.substr(nested + 4, peek<uint32_t>(b, nested)) != openvdb::math::AffineMap::mapType())
                 throw std::runtime_error("the frustum's linear map is not affine");
             for (int i = 0; i < 16; ++i) poke<double>(b, nested + 4 + 9 + 8 * std::size_t(i), 0.0);
         },
         "transform 'NonlinearFrustumMap', transform 'AffineMap': the matrix is singular or not finite"},
        {"scale-zero", kManta, [](std::string& b, const FileLayout& l) { poke<double>(b, l.grid("density").transform + 4 + 15, 0.0); },
         "transform 'UniformScaleMap': a scale is zero"},
        {"scale-translate-zero", kField,
         [](std::string& b, const FileLayout& l) { poke<double>(b, velocity(l).transform + 4 + 24 + 3 * 8, 0.0); },
         "transform 'UniformScaleTranslateMap': a scale is zero"},
        {"map-type", kField, [](std::string& b, const FileLayout& l) { b[velocity(l).transform + 4 + 23] = 'q'; },
         "map type 'UniformScaleTranslateMaq' is not an OpenVDB map"},
        {"map-not-finite", kField,
         [](std::string& b, const FileLayout& l) { poke<double>(b, velocity(l).transform + 4 + 24, std::numeric_limits<double>::quiet_NaN()); },
         "transform 'UniformScaleTranslateMap': a value is not finite"},
        // -- blosc blocks (a vec3s leaf: 6144 bytes) ----------------------------------------------
        {"blosc-short", kField, [](std::string& b, const FileLayout&) { poke<int64_t>(b, fullLeafBlosc(b) - 8, 8); },
         "a blosc block of 8 bytes is shorter than its header"},
        {"blosc-cbytes", kField,
         [](std::string& b, const FileLayout&) {
             const std::size_t at = fullLeafBlosc(b);
             poke<uint32_t>(b, at + 12, peek<uint32_t>(b, at + 12) + 1);
         },
         "bytes says it has"},
        {"blosc-nbytes", kField, [](std::string& b, const FileLayout&) { poke<uint32_t>(b, fullLeafBlosc(b) + 4, 8182); },
         "a blosc block claims 8182 bytes where 6144 are expected"},
        {"blosc-blocksize", kField, [](std::string& b, const FileLayout&) { poke<uint32_t>(b, fullLeafBlosc(b) + 8, 0); },
         "a blosc block has a block size of 0 for 6144 bytes"},
        {"blosc-blocksize", kField, [](std::string& b, const FileLayout&) { poke<uint32_t>(b, fullLeafBlosc(b) + 8, 6145); },
         "a blosc block has a block size of 6145 for 6144 bytes"},
        {"blosc-memcpyed", kField,
         [](std::string& b, const FileLayout&) {
             const std::size_t at = fullLeafBlosc(b);
             if (peek<uint32_t>(b, at + 12) >= 6144 + 16) throw std::runtime_error("the block is not compressed");
             b[at + 2] = char(b[at + 2] | 0x2); // BLOSC_MEMCPYED: the data would be the values, raw
         },
         "an uncompressed blosc block of"},
        {"blosc-header", kField, [](std::string& b, const FileLayout&) { b[fullLeafBlosc(b)] = char(0xFF); }, // a format from the future
         "a blosc block has an invalid header"},
        {"blosc-decode", kField, [](std::string& b, const FileLayout&) { poke<int32_t>(b, fullLeafBlosc(b) + 16, 0x7FFFFFF0); }, // 1st block's start
         "a blosc block does not decode to its 6144 bytes"},
        // -- zip, blosc or raw blocks ---------------------------------------------------------------
        {"raw-size", kField, [](std::string& b, const FileLayout&) { poke<int64_t>(b, fullLeafBlosc(b) - 8, -1); },
         "the leaf's values stores 1 uncompressed bytes where 6144 are expected"},
        {"block-bound", kField, [](std::string& b, const FileLayout&) { poke<int64_t>(b, fullLeafBlosc(b) - 8, int64_t(1) << 40); },
         "the leaf's values claims a blosc block of 1099511627776 bytes; 6144 bytes compress to at most 6160"},
        {"block-cut-short", kField,
         [](std::string& b, const FileLayout& l) { // the last block of the file one byte longer
             const ValueBlock& v = velocity(l).leafValues.back();
             const auto n = peek<int64_t>(b, v.data);
             if (v.data + 8 + std::size_t(n) != b.size() || uint64_t(n) + 1 > v.bytes + 16)
                 throw std::runtime_error("the file does not end with a compressed leaf block");
             poke<int64_t>(b, v.data, n + 1);
         },
         "the leaf's values is cut short at byte"},
        {"zip-decode", kSplit,
         [](std::string& b, const FileLayout& l) { // the zlib stream's checksum
             const ValueBlock& v = l.grid("vel.x").leafValues.at(0);
             const auto n = peek<int64_t>(b, v.data);
             if (n <= 0) throw std::runtime_error("the leaf block is not zipped");
             b[v.data + 8 + std::size_t(n) - 1] = char(b[v.data + 8 + std::size_t(n) - 1] ^ 0x55);
         },
         "a zip block does not decode to its"},
        {"mask-byte", kField, [](std::string& b, const FileLayout& l) { b[velocity(l).leafValues.at(0).compressionByte] = 7; },
         "the leaf's values: compression byte 7 is not 0 to 6"},
        // -- the tree ----------------------------------------------------------------------------
        {"buffer-count", kField, [](std::string& b, const FileLayout& l) { poke<int32_t>(b, velocity(l).tree, 2); },
         "grid 'velocity', tree: buffer count is 2, not 1"},
        {"root-counts", kField, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, velocity(l).tree + 4 + 12, 0xFFFFFFFFu); },
         "its root claims 4294967295 tiles and 1 children, more than the file can hold"},
        {"root-origin-align", kField, [](std::string& b, const FileLayout& l) { poke<int32_t>(b, velocity(l).children.at(0), 8); },
         "a root child (8, 0, 0) is not a multiple of 4096"},
        {"root-origin-range", kField,
         [](std::string& b, const FileLayout& l) { poke<int32_t>(b, velocity(l).children.at(0), (1 << 30) + 4096); },
         "a root child (1073745920, 0, 0) lies outside the index range licvdb reads"},
        {"root-origin-twice", kAllBlosc,
         [](std::string& b, const FileLayout& l) { // the child moved onto the inactive root tile at 8192
             const GridLayout& g = l.grid("float_tiles");
             std::memcpy(&b[g.children.at(0)], &b[g.tiles.at(0)], 12);
         },
         "a root child (8192, 8192, 8192) appears twice"},
        {"node2-child-and-value", kField, [](std::string& b, const FileLayout& l) { markChildActive(b, velocity(l).node2.at(0), 512); },
         "tree, node at (0, 0, 0): a slot is marked both child and active value"},
        {"node1-child-and-value", kField, [](std::string& b, const FileLayout& l) { markChildActive(b, velocity(l).node1.at(0), 64); },
         "tree, node at (0, 0, 0), node at (0, 0, 0): a slot is marked both child and active value"},
        {"leaf-mask-cut-short", kStreamed, [](std::string& b, const FileLayout& l) { b.resize(velocity(l).leafTopology.back() + 10); },
         "its value mask is cut short at byte"},
        {"leaf-mask-differs", kField, [](std::string& b, const FileLayout& l) { b[velocity(l).leafBuffers.at(0)] ^= 1; },
         "the leaf's value mask differs from the one in the tree's topology"},
        {"leaf-origin", kAllBlosc, [](std::string& b, const FileLayout& l) { poke<int32_t>(b, l.grid("mask").leafBuffers.at(0) + 64, 8); },
         "grid 'mask', leaf at (-104, 0, 0): the leaf says its origin is (8, 0, 0)"},
        // -- the table of grids and the grids' offsets -----------------------------------------
        {"grid-count-negative", kField, [](std::string& b, const FileLayout& l) { poke<int32_t>(b, l.gridCount, -1); },
         "the grid count is -1"},
        {"grid-count", kField, [](std::string& b, const FileLayout& l) { poke<int32_t>(b, l.gridCount, 0x7FFFFFFF); },
         "it claims 2147483647 grids, more than the file can hold"},
        {"grid-name-twice", kSplit, [](std::string& b, const FileLayout& l) { b[l.grid("vel.y").nameAt + 4 + 4] = 'x'; },
         "grid 'vel.x': the grid name appears twice"},
        {"grid-type", kField, [](std::string& b, const FileLayout& l) { b[velocity(l).typeAt + 4 + 9] = 'q'; },
         "grid type 'Tree_vec3q_5_4_3' is not an OpenVDB grid type"},
        {"half-grid", kField,
         [](std::string& b, const FileLayout& l) { // OpenVDB 13's HalfGrid type name
             const std::size_t at = velocity(l).typeAt;
             const std::string type = "Tree_half_5_4_3";
             const uint32_t n = uint32_t(type.size());
             b.replace(at, 4 + peek<uint32_t>(b, at), std::string(reinterpret_cast<const char*>(&n), 4) + type);
         },
         "is a half-precision grid (Tree_half_5_4_3, OpenVDB 13's HalfGrid), which licvdb does not read"},
        {"instance-parent", kAllBlosc, [](std::string& b, const FileLayout& l) { b[l.grid("float_instance").parent + 4 + 10] = 'z'; },
         "its instance parent 'float_tilez' is not an earlier grid of the same type"},
        {"instance-parent", kAllBlosc, [](std::string& b, const FileLayout& l) { b.replace(l.grid("float_instance").typeAt + 4, 16, "Tree_int32_5_4_3"); },
         "grid 'float_instance': its instance parent 'float_tiles' is not an earlier grid of the same type"},
        {"grid-end", kField, [](std::string& b, const FileLayout& l) { poke<int64_t>(b, velocity(l).offsets + 16, int64_t(b.size()) + 1); },
         "grid 'velocity' should end at byte"},
        {"grid-offsets", kField, [](std::string& b, const FileLayout& l) { poke<int64_t>(b, velocity(l).offsets, velocity(l).gridPos + 1); },
         "grid 'velocity' has inconsistent offsets"},
        {"compression-flags", kField, [](std::string& b, const FileLayout& l) { poke<uint32_t>(b, velocity(l).compression, 0x6 | 0x10); },
         "compression flags 22 are not OpenVDB's"},
        {"instance-end", kAllBlosc,
         [](std::string& b, const FileLayout& l) {
             const GridLayout& g = l.grid("float_instance");
             poke<int64_t>(b, g.offsets + 16, g.endPos - 1);
         },
         "grid 'float_instance': the instance's offsets do not match its contents"},
        {"streamed-unsupported", kStreamed,
         [](std::string& b, const FileLayout& l) { // a point index grid: no offsets to skip it by
             const std::size_t at = velocity(l).typeAt;
             std::string type = openvdb::tools::PointIndexGrid::gridType();
             const uint32_t n = uint32_t(type.size());
             b.replace(at, 4 + peek<uint32_t>(b, at), std::string(reinterpret_cast<const char*>(&n), 4) + type);
         },
         "in a streamed file (no grid offsets), which licvdb cannot skip: point grids are not read by licvdb"},
        {"topology-end", kField, [](std::string& b, const FileLayout& l) { poke<int64_t>(b, velocity(l).offsets + 8, velocity(l).blockPos + 1); },
         "the tree's topology ends at byte"},
        {"data-end", kField, [](std::string& b, const FileLayout& l) { poke<int64_t>(b, velocity(l).offsets + 16, velocity(l).endPos - 1); },
         "the grid's data ends at byte"},
    };
}

} // namespace

// The walk that finds the places to break agrees with every sample's own offsets.
TEST_F(VdbCheckRulesTest, LayoutOfEverySampleEndsWhereItsOffsetsSay)
{
    for (const auto& entry : fs::directory_iterator(sDir / "samples")) {
        SCOPED_TRACE(entry.path().filename().string());
        const std::string bytes = readFile(entry.path());
        const FileLayout l = layoutOf(bytes);
        ASSERT_FALSE(l.grids.empty());
        for (const auto& g : l.grids) {
            SCOPED_TRACE(g.name);
            if (g.endPos > 0) {
                EXPECT_EQ(g.end, std::size_t(g.endPos));
                if (g.tree) {
                    EXPECT_EQ(g.leafBuffers.empty() ? std::size_t(g.blockPos) : g.leafBuffers.front(), std::size_t(g.blockPos));
                }
            }
            if (g.tree) {
                EXPECT_EQ(g.leafTopology.size(), g.leafBuffers.size());
            }
        }
        EXPECT_EQ(l.grids.back().end, bytes.size());
    }
}

TEST_F(VdbCheckRulesTest, EachRuleRefusesItsOwnCorruption)
{
    int n = 0;
    for (const RuleCase& c : ruleCases()) {
        SCOPED_TRACE(std::string(c.rule) + " on " + c.sample + " (case " + std::to_string(n) + ")");
        std::string bytes = sample(c.sample);
        const FileLayout l = layoutOf(bytes);
        ASSERT_NO_THROW(c.edit(bytes, l));
        const fs::path path = file(std::to_string(n++) + "_" + c.rule + ".vdb");
        writeFile(path, bytes);
        expectRefusedBy(path.string(), c.rule, c.fragment);
    }
}

// ---- rules about the file as a whole ----------------------------------------------------------

TEST_F(VdbCheckRulesTest, PathsThatAreNoFileAreRefusedByName)
{
    expectRefusal(inputErrorOf([] { vdbexport::checkVdbStructure(""); }), "no-path", "no .vdb file given");
    expectRefusedBy(file("missing.vdb").string(), "not-found", "not found; expected a .vdb file");
    expectRefusal(inputErrorOf([] { vdbexport::checkVdbStructure(sDir.string()); }), "directory",
                  "is a directory; expected a .vdb file");
    writeFile(file("empty.vdb"), "");
    expectRefusedBy(file("empty.vdb").string(), "empty", "is empty (0 bytes)");
}

// A UNIX socket is neither a directory nor empty, but cannot be opened: refused by name (root too).
TEST_F(VdbCheckRulesTest, AFileThatCannotBeOpenedIsRefused)
{
    const fs::path path = sDir / "sock.vdb"; // short: sun_path holds 108 bytes
    const int fd = ::socket(AF_UNIX, SOCK_STREAM, 0);
    ASSERT_GE(fd, 0);
    sockaddr_un addr{};
    addr.sun_family = AF_UNIX;
    ASSERT_LT(path.string().size(), sizeof(addr.sun_path));
    std::strcpy(addr.sun_path, path.c_str());
    ASSERT_EQ(::bind(fd, reinterpret_cast<const sockaddr*>(&addr), sizeof(addr)), 0) << std::strerror(errno);
    expectRefusal(inputErrorOf([&] { vdbexport::checkVdbStructure(path.string()); }), "open",
                  "for reading (No such device or address); expected a readable .vdb file");
    ::close(fd);
    fs::remove(path);
}

// A named pipe opens but cannot seek: refused, never read as a stream.
TEST_F(VdbCheckRulesTest, APipeIsRefusedAsNotSeekable)
{
    const fs::path path = file("pipe.vdb");
    ASSERT_EQ(::mkfifo(path.c_str(), 0600), 0) << std::strerror(errno);
    std::thread writer([&] { // opens the write end once the check has opened the read end, then closes it
        const auto t0 = std::chrono::steady_clock::now();
        while (std::chrono::steady_clock::now() - t0 < std::chrono::seconds(20)) {
            const int fd = ::open(path.c_str(), O_WRONLY | O_NONBLOCK);
            if (fd >= 0) {
                ::close(fd);
                return;
            }
            std::this_thread::sleep_for(std::chrono::milliseconds(5));
        }
    });
    expectRefusal(inputErrorOf([&] { vdbexport::checkVdbStructure(path.string()); }), "not-seekable",
                  "cannot seek in the file");
    writer.join();
}

// The memory the grids would need, against the limit (LICVDB_READ_MEMORY_MB stands in for a
// machine too small for the file).
TEST_F(VdbCheckRulesTest, AFileThatNeedsMoreMemoryThanAllowedIsRefused)
{
    const std::string path = (sDir / "samples" / kAllBlosc).string();
    const auto r = vdbexport::checkVdbStructure(path);
    ASSERT_GT(r.memoryBytes, 2u << 20) << "the sample needs too little memory for this test";
    ::setenv("LICVDB_READ_MEMORY_MB", "1", 1);
    EXPECT_EQ(vdbexport::readMemoryLimitBytes(), 1u << 20);
    const std::string msg = inputErrorOf([&] { vdbexport::checkVdbStructure(path); });
    ::unsetenv("LICVDB_READ_MEMORY_MB");
    expectRefusal(msg, "memory", "MiB of memory to read, more than the 1 MiB allowed");
    EXPECT_NE(msg.find(std::to_string(r.memoryBytes >> 20) + " MiB of memory"), std::string::npos) << msg;
    EXPECT_NO_THROW(vdbexport::checkVdbStructure(path));
}

// ---- what the marker tells apart ----------------------------------------------------------------

TEST_F(VdbCheckRulesTest, OnlyLayerOneRefusalsCarryTheMarker)
{
    EXPECT_EQ(vdbexport::vdbCheckRule("[vdb-check grid-end] 'x.vdb' is truncated"), "grid-end");
    EXPECT_EQ(vdbexport::vdbCheckRule("licvdb bake: error: all 2 ranks failed while reading the field: [vdb-check grid-end] 'x'"),
              "grid-end");
    EXPECT_EQ(vdbexport::vdbCheckRule("cannot read 'x.vdb' (reading grids): IoError"), "");
    EXPECT_EQ(vdbexport::vdbCheckRule("[vdb-check unterminated"), "");
}

// Every rule (throw site) of VdbCheck.cpp is either broken by a file above or named here with the
// reason no file can reach it, so that a new rule cannot go untested.
TEST_F(VdbCheckRulesTest, EveryRuleIsTestedOrKnownUnreachable)
{
    const std::string source = readFile(fs::path(LICVDB_SOURCE_DIR) / "vdbexport/src/io/VdbCheck.cpp");
    std::set<std::string> rules;
    std::size_t sites = 0;
    const std::regex site(R"re(throw (corrupt|truncated|refusal)\("([a-z0-9-]+)")re");
    for (auto it = std::sregex_iterator(source.begin(), source.end(), site); it != std::sregex_iterator(); ++it, ++sites)
        EXPECT_TRUE(rules.insert((*it)[2]).second) << "two throw sites share rule " << (*it)[2];
    std::size_t throws = 0;
    for (std::size_t at = source.find("throw "); at != std::string::npos; at = source.find("throw ", at + 1)) ++throws;
    EXPECT_EQ(sites, throws) << "a throw without a rule name";
    EXPECT_EQ(sites, 70u);

    std::set<std::string> tested{"no-path", "not-found", "directory", "empty", "open", "not-seekable", "memory"};
    for (const RuleCase& c : ruleCases()) tested.insert(c.rule);
    // Unreachable from a file: see the comment at each throw site in VdbCheck.cpp.
    const std::set<std::string> unreachable{"no-size", "read-failed", "skip-failed", "seek", "meta-type", "delayed-end",
                                            "blosc-overrun"};
    for (const auto& r : rules) EXPECT_TRUE(tested.count(r) + unreachable.count(r) == 1) << "rule " << r;
    for (const auto& r : tested) EXPECT_TRUE(rules.count(r)) << "no rule " << r << " in VdbCheck.cpp";
    std::cout << "[ rules    ] " << rules.size() << " rules: " << tested.size() << " refuse a file of their own here, "
              << unreachable.size() << " cannot be reached from a file\n";
}
