// Trace one streamline of the rotation preset with lic::lic and check it stays on its circle.
#include <lic/field/Field.h>
#include <lic/field/Presets.h>
#include <lic/engine/Streamline.h>

#include <cmath>
#include <cstdio>
#include <vector>

int main()
{
    const lic::PresetField preset = lic::makePresetField("rotation", openvdb::Coord(32, 32, 8));
    const lic::VelocityField field(preset.velocity);
    const openvdb::Vec3d seed = field.worldBBox().getCenter() + openvdb::Vec3d(0.3 * field.worldBBox().extents()[0], 0, 0);
    lic::TraceSettings settings;
    settings.step = 0.5 * field.voxelSize()[0];
    settings.maxSamples = 40;
    std::vector<openvdb::Vec3d> line;
    lic::traceStreamline(field, seed, 1.0, settings, line, [](const openvdb::Vec3d&) { return true; });
    const openvdb::Vec3d c = field.worldBBox().getCenter();
    const double r0 = std::hypot(seed[0] - c[0], seed[1] - c[1]);
    double worst = 0;
    for (const auto& p : line) worst = std::max(worst, std::abs(std::hypot(p[0] - c[0], p[1] - c[1]) - r0));
    std::printf("trace: %zu samples, radius %.4f, largest drift %.2e (licvdb %s)\n", line.size(), r0, worst,
                LICVDB_VERSION);
    return line.size() == 40 && worst < 1e-3 * r0 ? 0 : 1;
}
