// `licvdb render`: raycast a baked .vdb (or a sequence, or a bake's manifest) to images.
#include "Command.h"
#include "Progress.h"

#include "vdbexport/render/Render.h"

#include <cstdio>
#include <iostream>
#include <string>

namespace vdbexport::cli {

namespace {

class RenderCommand final : public CommandWithCommonOptions
{
public:
    void addOptions(CLI::App& cmd) override;
    int run(Context& context) override;

private:
    void addCameraOptions(CLI::App& cmd);
    void addLookOptions(CLI::App& cmd);
    void addOutputOptions(CLI::App& cmd);
    /// The job with every flag applied.
    RenderJob job() const;

    RenderJob mJob;
    RenderFlagStrings mFlags;
    double mAzimuth = 0, mElevation = 0, mDistance = 0, mEyeSeparation = 0;
    CLI::Option *mAzimuthOption = nullptr, *mElevationOption = nullptr, *mDistanceOption = nullptr,
                *mEyeSeparationOption = nullptr;
    bool mNoSkipping = false;
};

void RenderCommand::addOptions(CLI::App& cmd)
{
    cmd.add_option("input", mJob.input, "Baked .vdb (a `density` grid), first frame OUT_0001.vdb, or a bake's manifest OUT.licvdb.json")->required();
    cmd.add_option("-o,--out", mJob.output, "Image: .png/.jpg/.tif (display, via OCIO), .exr (scene-linear), .gif")->required();
    addCameraOptions(cmd);
    addLookOptions(cmd);
    addOutputOptions(cmd);
    addCommonOptions(cmd, mCommon);
    cmd.footer(
        "Examples:\n"
        "  licvdb render jet_lic.vdb --out jet.png\n"
        "  licvdb render jet_lic.vdb --out jet.exr --view right --elevation 20 --size 1920,1080\n"
        "  licvdb render jet_lic.vdb --out jet.png --density-range 0.8,1 --view-transform filmic\n"
        "  licvdb render jet_lic.vdb --out jet_sbs.png --stereo sbs\n"
        "  licvdb render loop_0001.vdb --frames 24 --out loop.png --gif     # loop_0001.png … + loop.gif\n"
        "See docs/render.md for the algorithm, the transfer function and the --json camera.\n");
}

void RenderCommand::addCameraOptions(CLI::App& cmd)
{
    cmd.add_option("--size", mFlags.size, "Image size W,H in pixels [1024,1024]");
    cmd.add_option("--view", mFlags.view, "front|back|left|right|top|bottom (Blender's, Z up) [front]");
    cmd.add_flag("--ortho", mJob.camera.orthographic, "Orthographic camera (default perspective)");
    mAzimuthOption = cmd.add_option("--azimuth", mAzimuth, "Degrees about +Z from the front view (90 = right view); overrides --view's");
    mElevationOption = cmd.add_option("--elevation", mElevation, "Degrees above the horizon (90 = top view); overrides --view's");
    mDistanceOption = cmd.add_option("--distance", mDistance, "Camera distance from the bbox centre, world units [fit]");
    cmd.add_option("--fov", mJob.camera.fovY, "Vertical field of view, degrees [30]");
}

void RenderCommand::addLookOptions(CLI::App& cmd)
{
    RenderJob& j = mJob;
    cmd.add_option("--halos", mFlags.halos, "on|off: halo compositing when the file has a `halo` grid [on]");
    cmd.add_option("--halo-strength", j.settings.haloStrength, "Opacity added at a halo exit per unit of its max halo [1]");
    cmd.add_option("--halo-threshold", j.settings.haloThreshold, "A ray is inside a halo where halo > this [0.05]");
    cmd.add_option("--density-scale", j.settings.densityScale, "Extinction per unit density per voxel length [auto: 2 with a halo grid, else fit]");
    cmd.add_option("--density-range", mFlags.densityRange,
                   "LO,HI transfer window on density, or auto (from the density's percentiles) [auto for a noise bake, else 0,1]");
    cmd.add_option("--brightness", j.settings.brightness, "Emission multiplier [1]");
    cmd.add_option("--step", j.settings.step, "Ray step, voxels [0.5]");
    cmd.add_flag("--no-skipping", mNoSkipping, "Diagnostic: march empty 8^3 bricks too (same image, slower)");
    cmd.add_option("--colormap", j.colormap, "Colour by the `scalar` grid: a colormap name or value,r,g,b .csv");
    cmd.add_option("--field", j.field, "Velocity .vdb: line tangents for lighting when there is no `tangent` grid");
    cmd.add_option("--light", mFlags.light, "headlight | X,Y,Z (direction towards the light) | off [headlight]");
}

void RenderCommand::addOutputOptions(CLI::App& cmd)
{
    cmd.add_option("--stereo", mFlags.stereo, "sbs (side by side, 2W wide) | anaglyph (red-cyan)");
    mEyeSeparationOption = cmd.add_option("--eye-separation", mEyeSeparation, "Stereo eye distance, world units [distance/30]");
    cmd.add_option("--frames", mJob.frames, "Render the sequence IN_0001.vdb … IN_000N.vdb to IMAGE_0001 …");
    cmd.add_flag("--gif", mJob.gif, "With a sequence, also write an animated IMAGE.gif");
    cmd.add_option("--fps", mJob.fps, "GIF frame rate [12]");
    cmd.add_option("--view-transform", mJob.viewTransform, "standard|filmic|raw (OCIO view for .png/.jpg/.tif/.gif) [standard]");
    cmd.add_option("--ocio-config", mJob.ocioConfig, "OCIO config [$LICVDB_OCIO_CONFIG, else the shipped one]");
}

RenderJob RenderCommand::job() const
{
    RenderJob job = mJob;
    applyRenderFlags(job, mFlags);
    if (mAzimuthOption->count()) job.azimuth = mAzimuth;
    if (mElevationOption->count()) job.elevation = mElevation;
    if (mDistanceOption->count()) job.camera.distance = mDistance;
    if (mEyeSeparationOption->count()) job.eyeSeparation = mEyeSeparation;
    job.settings.threads = mCommon.threads;
    job.settings.emptySpaceSkipping = !mNoSkipping;
    return job;
}

/// `v` as printf's %g (0.7564, 1, 99.9).
std::string fmtNumber(double v)
{
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", v);
    return buf;
}

/// The automatic density window, one line on stderr (nothing when the window was given or 0,1).
void printDensityRange(const nlohmann::json& settings)
{
    if (!settings["density_range_auto"].get<bool>()) return;
    const auto& range = settings["density_range"];
    const auto& pct = settings["density_range_percentiles"];
    const std::string how = pct.is_array()
        ? "the " + fmtNumber(pct[0].get<double>()) + "th to " + fmtNumber(pct[1].get<double>()) + "th percentile of the density"
        : std::string("the percentiles of the density leave no window, so 0 to its largest value");
    std::fprintf(stderr, "density range %s,%s (auto: %s; --density-range LO,HI to set it)\n",
                 fmtNumber(range[0].get<double>()).c_str(), fmtNumber(range[1].get<double>()).c_str(), how.c_str());
}

int RenderCommand::run(Context&)
{
    const RenderJob j = job();
    const nlohmann::json summary = runWithProgress(mCommon.quiet, mCommon.progressStyle(),
                                                   [&](lic::Progress& progress) { return render(j, progress); });
    if (mCommon.json) {
        std::cout << summary.dump(2) << "\n";
    } else if (!mCommon.quiet) {
        printDensityRange(summary["settings"]);
        for (const auto& f : summary["files"]) std::fprintf(stderr, "wrote %s\n", f.get<std::string>().c_str());
        std::fprintf(stderr, "rendered %d frame(s) in %.2f s\n", summary["frames"].get<int>(),
                     summary["seconds"]["render"].get<double>());
    }
    return 0;
}

} // namespace

std::unique_ptr<Command> makeRenderCommand() { return std::make_unique<RenderCommand>(); }

} // namespace vdbexport::cli
