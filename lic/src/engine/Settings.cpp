#include "lic/engine/Settings.h"

#include "lic/util/Error.h"
#include "lic/util/Names.h"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace lic {

const char* toString(KernelType k) { return nameOf<KernelType>(kKernelNames, k); }

KernelType kernelFromString(const std::string& s) { return valueOf<KernelType>(kKernelNames, s, "kernel"); }

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
    if (kernel == KernelType::Exp && !(decay > 0 && decay < 1)) fail("decay", decay, "in (0, 1)");
    if (minHits < 1 || minHits > 64) fail("min_hits", minHits, "1..64");
    if (threads < 0) fail("threads", threads, ">= 0 (0 = all cores)");
    if (coveredRun < 1) fail("covered run", coveredRun, ">= 1");
    if (maxStreamline < 0) fail("max streamline", maxStreamline, ">= 0");
    if (brick != 0 && (brick < 8 || brick > 512 || brick % 8 != 0))
        fail("brick", brick, "a multiple of 8 in 8..512 output voxels (0 = automatic)");
    if (stride < 0 || stride > 64) fail("stride", stride, "0..64 samples per integration step (0 = automatic)");
    if (comets < 0 || comets == 1 || comets > 10000) fail("comet frames", comets, "0 (none) or 2..10000");
    if (comets > 0 && ripple) throw InputError("a loop has either ripple sums or comets, not both");
    if (comets > 0 && engine == EngineType::Naive)
        throw InputError("comet loops are made by the splat and fast engines (spot input); the naive engine makes ripple loops");
}

namespace detail {

TraceSettings traceSettings(const VelocityField& field, const OutputDomain& domain, const LicSettings& settings)
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

int integrationStride(const OutputDomain& domain, const LicSettings& settings)
{
    if (settings.stride > 0) return settings.stride;
    // About one field voxel per RK4 step (the trilinear field has no detail finer than that).
    return std::clamp(int(std::floor(double(domain.upsample()) / settings.step + 1e-9)), 1, 8);
}

} // namespace detail
} // namespace lic
