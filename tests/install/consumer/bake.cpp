// Bake a small LIC volume with lic::vdbexport: bake OUT.vdb (writes OUT.vdb + OUT.licvdb.json).
#include <lic/util/Error.h>
#include <lic/field/Presets.h>
#include <vdbexport/bake/Bake.h>
#include <vdbexport/bake/Recipe.h>

#include <openvdb/openvdb.h>

#include <cstdio>
#include <filesystem>

int main(int argc, char** argv)
{
    if (argc != 2) {
        std::fprintf(stderr, "usage: bake OUT.vdb\n");
        return 2;
    }
    try {
        openvdb::initialize();
        const std::filesystem::path out(argv[1]);
        const std::filesystem::path fieldPath = out.parent_path() / "consumer_field.vdb";
        lic::PresetField preset = lic::makePresetField("abc", openvdb::Coord(16, 16, 16));
        openvdb::io::File(fieldPath.string()).write({preset.velocity});
        vdbexport::Recipe recipe = vdbexport::parseRecipe(
            R"({"field": {"path": ")" + fieldPath.string() + R"("}, "output": {"path": ")" + out.string() +
            R"(", "upsample": 1}, "lic": {"length": 4}})");
        const nlohmann::json summary = vdbexport::bake(recipe);
        std::printf("bake: %s and %s\n", summary["files"][0].get<std::string>().c_str(),
                    summary["manifest"].get<std::string>().c_str());
        return std::filesystem::is_regular_file(vdbexport::manifestPath(out.string())) ? 0 : 1;
    } catch (const lic::Error& e) {
        std::fprintf(stderr, "bake: error: %s\n", e.what());
        return 1;
    }
}
