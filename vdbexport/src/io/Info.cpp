#include "vdbexport/io/Info.h"

#include "vdbexport/io/VdbReader.h"

#include <openvdb/openvdb.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <limits>
#include <set>
#include <sstream>
#include <type_traits>
#include <vector>

namespace vdbexport {

namespace {

using nlohmann::json;

/// A float as the double with the same shortest decimal form (0.1f → 0.1, not 0.100000001…).
double shortestDouble(float f)
{
    if (!std::isfinite(f)) return static_cast<double>(f);
    char buf[64];
    const auto res = std::to_chars(buf, buf + sizeof(buf), f);
    double d = static_cast<double>(f);
    std::from_chars(buf, res.ptr, d);
    return d;
}

json number(float v) { return shortestDouble(v); }
json number(double v) { return v; }
json number(int32_t v) { return v; }

template<typename VecT>
json vectorToJson(const VecT& v)
{
    json a = json::array();
    for (int i = 0; i < VecT::size; ++i) a.push_back(number(v[i]));
    return a;
}

json coordToJson(const openvdb::Coord& c) { return json::array({c.x(), c.y(), c.z()}); }

template<typename MatT>
json matrixToJson(const MatT& m)
{
    json rows = json::array();
    for (int r = 0; r < 4; ++r) {
        json row = json::array();
        for (int c = 0; c < 4; ++c) row.push_back(number(m(r, c)));
        rows.push_back(std::move(row));
    }
    return rows;
}

json stringToJson(const std::string& s)
{
    const auto first = s.find_first_not_of(" \t\r\n");
    if (first != std::string::npos && s[first] == '{') {
        json parsed = json::parse(s, nullptr, /*allow_exceptions=*/false);
        if (parsed.is_object()) return parsed;
    }
    return s;
}

json metadataToJson(const openvdb::Metadata& m)
{
    using namespace openvdb;
    if (auto p = dynamic_cast<const StringMetadata*>(&m)) return stringToJson(p->value());
    if (auto p = dynamic_cast<const BoolMetadata*>(&m)) return p->value();
    if (auto p = dynamic_cast<const Int32Metadata*>(&m)) return p->value();
    if (auto p = dynamic_cast<const Int64Metadata*>(&m)) return p->value();
    if (auto p = dynamic_cast<const FloatMetadata*>(&m)) return number(p->value());
    if (auto p = dynamic_cast<const DoubleMetadata*>(&m)) return number(p->value());
    if (auto p = dynamic_cast<const Vec2IMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec2SMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec2DMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec3IMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec3SMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec3DMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec4IMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec4SMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Vec4DMetadata*>(&m)) return vectorToJson(p->value());
    if (auto p = dynamic_cast<const Mat4SMetadata*>(&m)) return matrixToJson(p->value());
    if (auto p = dynamic_cast<const Mat4DMetadata*>(&m)) return matrixToJson(p->value());
    return m.str(); // unknown or unregistered type: its text form
}

json metaMapToJson(const openvdb::MetaMap& meta, const std::set<std::string>& skip = {})
{
    json out = json::object();
    for (auto it = meta.beginMeta(); it != meta.endMeta(); ++it) {
        if (!it->second || skip.count(it->first)) continue;
        out[it->first] = metadataToJson(*it->second);
    }
    return out;
}

/// Value range over the active values of a typed grid (magnitude for vectors), and the count
/// of non-finite active values (tiles counted by their voxel count).
struct RangeOp
{
    json range;
    uint64_t nonFinite = 0;

    template<typename T> static double scalar(const T& v) { return static_cast<double>(v); }
    static double scalar(bool v) { return v ? 1.0 : 0.0; }
    template<typename T> static double scalar(const openvdb::math::Vec3<T>& v)
    {
        const double x = v[0], y = v[1], z = v[2];
        return std::sqrt(x * x + y * y + z * z);
    }

    template<typename GridT>
    void operator()(const GridT& grid)
    {
        double lo = std::numeric_limits<double>::infinity();
        double hi = -lo;
        for (auto it = grid.cbeginValueOn(); it; ++it) {
            const double v = scalar(*it);
            if (!std::isfinite(v)) {
                nonFinite += it.getVoxelCount();
                continue;
            }
            lo = std::min(lo, v);
            hi = std::max(hi, v);
        }
        if (lo > hi) return;
        if constexpr (std::is_same_v<typename GridT::ValueType, float>
                      || std::is_same_v<typename GridT::ValueType, openvdb::Vec3s>) {
            range = json::array({shortestDouble(static_cast<float>(lo)), shortestDouble(static_cast<float>(hi))});
        } else {
            range = json::array({lo, hi});
        }
    }
};

using RangeGridTypes =
    openvdb::NumericGridTypes::Append<openvdb::Vec3GridTypes>::Append<openvdb::BoolGrid>;

json describeGrid(const openvdb::GridBase& grid)
{
    json g;
    g["name"] = grid.getName();
    g["value_type"] = grid.valueType();
    g["class"] = openvdb::GridBase::gridClassToString(grid.getGridClass());
    g["active_voxels"] = grid.activeVoxelCount();
    g["active_tiles"] = grid.baseTree().activeTileCount();
    g["leaf_nodes"] = grid.baseTree().leafCount();
    const openvdb::CoordBBox bbox = grid.evalActiveVoxelBoundingBox();
    if (bbox.empty()) {
        g["index_bbox"] = nullptr;
        g["world_bbox"] = nullptr;
    } else {
        g["index_bbox"] = json::array({coordToJson(bbox.min()), coordToJson(bbox.max())});
        const openvdb::BBoxd world = grid.constTransform().indexToWorld(
            openvdb::BBoxd(bbox.min().asVec3d() - openvdb::Vec3d(0.5), bbox.max().asVec3d() + openvdb::Vec3d(0.5)));
        g["world_bbox"] = json::array({vectorToJson(world.min()), vectorToJson(world.max())});
    }
    g["voxel_size"] = vectorToJson(grid.voxelSize());
    g["memory_bytes"] = grid.memUsage();
    RangeOp op;
    grid.apply<RangeGridTypes>(op);
    g["value_range"] = op.range;
    g["non_finite_values"] = op.nonFinite;
    static const std::set<std::string> skip = {
        openvdb::GridBase::META_GRID_NAME,       openvdb::GridBase::META_GRID_CLASS,
        openvdb::GridBase::META_FILE_BBOX_MIN,   openvdb::GridBase::META_FILE_BBOX_MAX,
        openvdb::GridBase::META_FILE_COMPRESSION, openvdb::GridBase::META_FILE_MEM_BYTES,
        openvdb::GridBase::META_FILE_VOXEL_COUNT, openvdb::GridBase::META_FILE_DELAYED_LOAD};
    g["metadata"] = metaMapToJson(grid, skip);
    return g;
}

// ---- text formatting ----------------------------------------------------------------------

constexpr std::size_t kMaxValueChars = 100;

std::string formatNumber(const json& v)
{
    if (v.is_number_integer() || v.is_number_unsigned()) return v.dump();
    if (v.is_number_float()) {
        char buf[32];
        std::snprintf(buf, sizeof(buf), "%.6g", v.get<double>());
        return buf;
    }
    return v.dump();
}

/// 1234567 → "1,234,567".
std::string withThousands(uint64_t n)
{
    const std::string digits = std::to_string(n);
    std::string s;
    s.reserve(digits.size() + digits.size() / 3);
    for (std::size_t i = 0; i < digits.size(); ++i) {
        if (i > 0 && (digits.size() - i) % 3 == 0) s.push_back(',');
        s.push_back(digits[i]);
    }
    return s;
}

std::string formatBytes(uint64_t bytes)
{
    const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB"};
    double v = static_cast<double>(bytes);
    int u = 0;
    while (v >= 1024.0 && u < 4) {
        v /= 1024.0;
        ++u;
    }
    char buf[32];
    if (u == 0) std::snprintf(buf, sizeof(buf), "%llu B", static_cast<unsigned long long>(bytes));
    else std::snprintf(buf, sizeof(buf), "%.1f %s", v, units[u]);
    return buf;
}

/// [1,2,3] → "(1, 2, 3)"; numbers via formatNumber.
std::string formatVector(const json& v)
{
    if (!v.is_array()) return v.is_null() ? "-" : formatNumber(v);
    std::string s = "(";
    for (std::size_t i = 0; i < v.size(); ++i) s += (i ? ", " : "") + formatNumber(v[i]);
    return s + ")";
}

std::string formatVoxelSize(const json& v)
{
    if (v.is_array() && v.size() == 3 && v[0] == v[1] && v[1] == v[2]) return formatNumber(v[0]);
    return formatVector(v);
}

/// A metadata value on one line: strings bare, numbers short, everything else compact JSON,
/// cut to about kMaxValueChars with "…" (never inside a UTF-8 sequence).
std::string formatValue(const json& v)
{
    std::string s;
    if (v.is_string()) s = v.get<std::string>();
    else if (v.is_number()) s = formatNumber(v);
    else if (v.is_array() && std::all_of(v.begin(), v.end(), [](const json& e) { return e.is_number(); }))
        s = formatVector(v);
    else s = v.dump(-1, ' ', false, json::error_handler_t::replace);
    std::replace(s.begin(), s.end(), '\n', ' ');
    if (s.size() > kMaxValueChars) {
        std::size_t cut = kMaxValueChars;
        while (cut > 0 && (static_cast<unsigned char>(s[cut]) & 0xC0) == 0x80) --cut;
        s = s.substr(0, cut) + "…";
    }
    return s;
}

std::string getString(const json& j, const char* key)
{
    const auto it = j.find(key);
    return it != j.end() && it->is_string() ? it->get<std::string>() : std::string();
}

uint64_t getCount(const json& j, const char* key)
{
    const auto it = j.find(key);
    return it != j.end() && it->is_number() ? it->get<uint64_t>() : 0;
}

void appendMetadata(std::ostringstream& out, const json& meta, const std::string& indent)
{
    if (!meta.is_object() || meta.empty()) {
        out << indent << "(none)\n";
        return;
    }
    std::size_t width = 0;
    for (const auto& [key, value] : meta.items()) width = std::max(width, key.size());
    for (const auto& [key, value] : meta.items())
        out << indent << key << std::string(width - key.size() + 2, ' ') << formatValue(value) << "\n";
}

} // namespace

json describeVdb(const std::string& path)
{
    detail::VdbReader reader(path);
    json out;
    out["path"] = path;
    out["file_metadata"] = metaMapToJson(*reader.fileMetadata());
    out["grids"] = json::array();
    for (const auto& grid : reader.readAllGrids())
        if (grid) out["grids"].push_back(describeGrid(*grid));
    return out;
}

std::string formatInfo(const json& d)
{
    std::ostringstream out;
    out << getString(d, "path") << "\n";
    if (d.contains("file_metadata") && d["file_metadata"].is_object() && !d["file_metadata"].empty()) {
        out << "  file metadata\n";
        appendMetadata(out, d["file_metadata"], "    ");
    }
    const json grids = d.contains("grids") && d["grids"].is_array() ? d["grids"] : json::array();
    if (grids.empty()) {
        out << "  no grids\n";
        return out.str();
    }

    // The table: one row per grid, columns padded to their widest cell.
    const std::vector<std::string> header = {"grid", "type", "class", "active voxels", "tiles",
                                             "leaves", "voxel size", "memory", "value range"};
    const std::vector<bool> rightAligned = {false, false, false, true, true, true, false, true, false};
    std::vector<std::vector<std::string>> rows = {header};
    for (const auto& g : grids) {
        std::string range = "-";
        if (g.contains("value_range") && g["value_range"].is_array() && g["value_range"].size() == 2) {
            const bool vec = getString(g, "value_type").rfind("vec", 0) == 0;
            range = (vec ? "|v| " : "") + formatNumber(g["value_range"][0]) + " .. "
                  + formatNumber(g["value_range"][1]);
        }
        if (getCount(g, "non_finite_values") > 0)
            range += " (" + withThousands(getCount(g, "non_finite_values")) + " non-finite)";
        const std::string name = getString(g, "name");
        rows.push_back({name.empty() ? "(unnamed)" : name, getString(g, "value_type"),
                        getString(g, "class"), withThousands(getCount(g, "active_voxels")),
                        withThousands(getCount(g, "active_tiles")), withThousands(getCount(g, "leaf_nodes")),
                        g.contains("voxel_size") ? formatVoxelSize(g["voxel_size"]) : "-",
                        formatBytes(getCount(g, "memory_bytes")), range});
    }
    std::vector<std::size_t> widths(header.size(), 0);
    for (const auto& row : rows)
        for (std::size_t c = 0; c < row.size(); ++c) widths[c] = std::max(widths[c], row[c].size());
    out << "\n";
    for (const auto& row : rows) {
        out << " ";
        for (std::size_t c = 0; c < row.size(); ++c) {
            const std::string pad(widths[c] - row[c].size(), ' ');
            const bool last = c + 1 == row.size();
            out << ' ';
            if (rightAligned[c]) out << pad << row[c];
            else out << row[c] << (last ? "" : pad);
            if (!last) out << ' ';
        }
        out << "\n";
    }

    // Per grid: bounding boxes and metadata.
    for (const auto& g : grids) {
        const std::string name = getString(g, "name");
        out << "\n" << (name.empty() ? "(unnamed)" : name) << "\n";
        const auto bbox = [&](const char* key) {
            if (!g.contains(key) || !g[key].is_array() || g[key].size() != 2) return std::string("empty");
            return formatVector(g[key][0]) + " .. " + formatVector(g[key][1]);
        };
        out << "  index bbox  " << bbox("index_bbox") << "\n";
        out << "  world bbox  " << bbox("world_bbox") << "\n";
        out << "  metadata\n";
        appendMetadata(out, g.contains("metadata") ? g["metadata"] : json::object(), "    ");
    }
    return out.str();
}

} // namespace vdbexport
