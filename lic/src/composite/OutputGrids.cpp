#include "lic/composite/OutputGrids.h"

#include "lic/util/Error.h"

namespace lic {

namespace {

constexpr GridMeta kVelocityMeta[] = {{"licvdb_velocity_unit", "world units per second"}};
constexpr GridMeta kColorMeta[] = {{"licvdb_color_space", "scene-linear Rec.709"}};

using enum OutputGrid;

constexpr OutputGridRow kGrids[] = {
    {.id = Density, .name = "density", .type = "float", .when = GridWhen::Always,
     .fill = "the LIC texture in [0, 1]: streaks along the flow (noise) or lines (spots); a fog volume",
     .metadata = "the resolved recipe (licvdb_recipe), ranges, engine and counts (lic_*), lic_frame",
     .blender = "emission and absorption of the lines", .perFrame = true},
    {.id = Halo, .name = "halo", .type = "float", .when = GridWhen::Spots,
     .fill = "the halo around each line in [0, 1], at least `density` wherever the line is",
     .blender = "the black shell behind the lines (look Halos)", .perFrame = true},
    {.id = LevelLines, .name = "density_w", .type = "float", .when = GridWhen::Asked, .recipeKey = "write_series",
     .flag = "--write-series", .help = "Spots: also write density_w<k> and halo_w<k> for every width level",
     .fill = "width level k's lines alone (without the width blend)", .blender = "not used", .perLevel = true,
     .perFrame = true},
    {.id = LevelHalos, .name = "halo_w", .type = "float", .when = GridWhen::Asked, .recipeKey = "write_series",
     .flag = "--write-series", .fill = "width level k's halos alone (without the width blend)", .blender = "not used",
     .perLevel = true, .perFrame = true},
    {.id = Input, .name = "input", .type = "float", .when = GridWhen::Asked, .recipeKey = "write_input",
     .flag = "--write-input", .help = "Also write the input texture as grid `input`",
     .fill = "the input texture that was convolved (noise, or the narrowest level's spots)", .blender = "not used"},
    {.id = Tangent, .name = "tangent", .type = "vec3s", .when = GridWhen::Asked, .recipeKey = "write_tangent",
     .flag = "--write-tangent", .help = "Also write the unit flow direction as vec3s grid `tangent`",
     .fill = "the unit flow direction at the voxel centre (0 at critical points)", .blender = "not used"},
    {.id = Velocity, .name = "velocity", .type = "vec3s", .when = GridWhen::Asked, .recipeKey = "write_velocity",
     .flag = "--write-velocity",
     .help = "Also write vec3s grid `velocity` (world units per second: the flow, or how a loop's lines travel) "
             "for motion blur",
     .fill = "how the lines move, world units per second: the flow (a still, each frame of a sequence), or how a "
             "loop's comets or ripples travel at field.fps",
     .metadata = "licvdb_velocity_unit; a loop's licvdb_loop_speed",
     .blender = "the volume's velocity grid (Cycles motion blur)", .vecType = openvdb::VEC_CONTRAVARIANT_RELATIVE,
     .fixedMeta = kVelocityMeta},
    {.id = Color, .name = "color", .type = "vec3s", .when = GridWhen::ColorScalar,
     .fill = "the colour scalar through the colormap, scene-linear Rec.709", .metadata = "licvdb_color_space",
     .blender = "the lines' colour (colour source Color)", .fixedMeta = kColorMeta},
    {.id = Scalar, .name = "scalar", .type = "float", .when = GridWhen::ColorScalar,
     .fill = "the colour scalar mapped from color.range onto [0, 1]",
     .blender = "the lines' colour through a ramp made from the bake's colormap (colour source Scalar)"},
};

static_assert(std::size(kGrids) == kOutputGridCount, "one row per OutputGrid");

} // namespace

std::span<const OutputGridRow> outputGrids() { return kGrids; }

const OutputGridRow& outputGrid(OutputGrid id)
{
    const OutputGridRow& row = kGrids[std::size_t(id)];
    if (row.id != id) throw Error("output grid table out of order");
    return row;
}

std::string outputGridName(OutputGrid id, int level)
{
    const OutputGridRow& row = outputGrid(id);
    return row.perLevel ? std::string(row.name) + std::to_string(level) : std::string(row.name);
}

OutputGridSet& OutputGridSet::setKey(std::string_view key, bool on)
{
    for (const OutputGridRow& row : kGrids)
        if (row.when == GridWhen::Asked && row.recipeKey == key) add(row.id, on);
    return *this;
}

bool OutputGridSet::hasKey(std::string_view key) const
{
    for (const OutputGridRow& row : kGrids)
        if (row.when == GridWhen::Asked && row.recipeKey == key) return has(row.id);
    return false;
}

} // namespace lic
