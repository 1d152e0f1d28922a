#include "lic/Engine.h"

#include "lic/Error.h"

#include <cmath>
#include <map>
#include <sstream>

namespace lic {

const char* toString(EngineType e) { return e == EngineType::Naive ? "naive" : "fast"; }

EngineType engineFromString(const std::string& s)
{
    if (s == "naive") return EngineType::Naive;
    if (s == "fast") return EngineType::Fast;
    throw InputError("engine \"" + s + "\" is unknown; expected naive or fast");
}

int LicSettings::halfSamples() const
{
    return std::max(1, int(std::lround(length / step)));
}

void LicSettings::validate() const
{
    auto fail = [](const std::string& what, double got, const std::string& expected) {
        std::ostringstream msg;
        msg << what << " " << got << " is out of range; expected " << expected;
        throw InputError(msg.str());
    };
    if (!(length > 0) || !std::isfinite(length)) fail("length", length, "> 0 output voxels");
    if (!(step > 0) || !std::isfinite(step)) fail("step", step, "> 0 output voxels");
    if (step > length) fail("step", step, "<= length (" + std::to_string(length) + ")");
    if (length / step > 1e6) fail("length/step", length / step, "at most 1e6 samples per direction");
    if (!(tolerance > 0)) fail("tolerance", tolerance, "> 0");
    if (minHits < 1 || minHits > 64) fail("min_hits", minHits, "1..64");
    if (threads < 0) fail("threads", threads, ">= 0 (0 = all cores)");
    if (coveredRun < 1) fail("covered run", coveredRun, ">= 1");
    if (maxStreamline < 0) fail("max streamline", maxStreamline, ">= 0");
}

namespace detail {

TraceSettings traceSettings(const VelocityField& field, const OutputDomain& domain,
                            const LicSettings& settings)
{
    const double vs = domain.voxelSize();
    TraceSettings ts;
    ts.step = settings.step * vs;
    ts.maxSamples = settings.halfSamples();
    ts.integrator = settings.integrator;
    ts.tolerance = settings.tolerance * vs;
    ts.maxStep = std::max(ts.step, 2.0 * vs);
    ts.minSpeed = field.maxSpeed() * 1e-6;
    return ts;
}

std::vector<FastTile> makeFastTiles(const OutputDomain& domain)
{
    constexpr int kTileLog2 = 5; // 32³ output voxels
    std::map<openvdb::Coord, std::size_t> index;
    std::vector<FastTile> tiles;
    for (std::size_t b = 0; b < domain.blockCount(); ++b) {
        const openvdb::Coord& o = domain.blockOrigin(b);
        const openvdb::Coord key(o[0] >> kTileLog2, o[1] >> kTileLog2, o[2] >> kTileLog2);
        auto [it, inserted] = index.try_emplace(key, tiles.size());
        if (inserted) tiles.emplace_back();
        tiles[it->second].blocks.push_back(std::uint32_t(b));
    }
    return tiles;
}

} // namespace detail
} // namespace lic
