// The grids a bake can write, one row each: name, value type, when it is written (always, spot
// bakes, asked for by a recipe key and flag, or with a colour scalar), what each active voxel
// holds, its metadata and how the Blender add-on uses it. The compositor makes the grids in the
// table's order (the order of a frame file), the recipe reads and writes the `output.write_*` keys
// from it, `licvdb bake` makes its `--write-*` flags from it, and `licvdb help --json` lists it for
// the docs and the add-on. A new grid is a row here and its fill in the compositor
// (Compositor::addStatic for a grid every frame shares).
#pragma once

#include <openvdb/Types.h>

#include <bitset>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>
#include <utility>

namespace lic {

/// The rows of outputGrids(), in file order.
enum class OutputGrid : std::uint8_t {
    Density,    ///< the LIC texture
    Halo,       ///< spots: the halo around each line
    LevelLines, ///< spots: each width level's lines, `density_w<k>`
    LevelHalos, ///< spots: each width level's halos, `halo_w<k>`
    Input,      ///< the texture that was convolved
    Tangent,    ///< unit flow direction
    Velocity,   ///< how the lines move, for motion blur
    Color,      ///< the colour scalar through the colormap
    Scalar,     ///< the colour scalar mapped onto [0, 1]
    Count
};
constexpr std::size_t kOutputGridCount = std::size_t(OutputGrid::Count);

/// When a grid is written.
enum class GridWhen : std::uint8_t {
    Always,     ///< every bake
    Spots,      ///< spot bakes
    Asked,      ///< asked for by its recipe key (`output.<key>`) and flag
    ColorScalar ///< with a colour scalar (recipe section `color`)
};

/// A grid's metadata entry with a fixed text value.
using GridMeta = std::pair<std::string_view, std::string_view>;

struct OutputGridRow
{
    OutputGrid id;
    std::string_view name;      ///< grid name; a per-level grid's name is this + k (1-based)
    std::string_view type;      ///< "float" or "vec3s"
    GridWhen when;
    std::string_view recipeKey = {}; ///< Asked: the key under `output` ("write_tangent"), else ""
    std::string_view flag = {};      ///< Asked: the bake flag ("--write-tangent"), else ""
    std::string_view help = {};      ///< Asked: the flag's help (rows sharing a flag: the first row's)
    std::string_view fill = {};      ///< what each active voxel holds
    std::string_view metadata = {};  ///< the grid's own metadata, as the docs describe it ("" = none)
    std::string_view blender = {};   ///< what the Blender add-on does with it
    bool perLevel = false;      ///< one grid per spot width level (`density_w1`, `density_w2`, ...)
    bool perFrame = false;      ///< composed for every frame of a loop; else shared by every frame
    /// Vector grids: how OpenVDB transforms the values (velocity: contravariant relative).
    openvdb::VecType vecType = openvdb::VEC_INVARIANT;
    /// Metadata with fixed values, inserted when the grid is made.
    std::span<const GridMeta> fixedMeta = {};
};

/// Every grid a bake can write, in file order.
std::span<const OutputGridRow> outputGrids();
const OutputGridRow& outputGrid(OutputGrid id);
/// The grid's name; a per-level grid's for width level `level` (1-based).
std::string outputGridName(OutputGrid id, int level = 0);

/// The Asked grids a recipe asks for (`output.write_*`).
class OutputGridSet
{
public:
    bool has(OutputGrid g) const { return mBits.test(std::size_t(g)); }
    OutputGridSet& add(OutputGrid g, bool on = true)
    {
        mBits.set(std::size_t(g), on);
        return *this;
    }
    /// Every grid of recipe key `key` ("write_series" is both level grids) on or off.
    OutputGridSet& setKey(std::string_view key, bool on);
    /// Whether the grids of recipe key `key` are asked for.
    bool hasKey(std::string_view key) const;
    bool operator==(const OutputGridSet&) const = default;

private:
    std::bitset<kOutputGridCount> mBits;
};

} // namespace lic
