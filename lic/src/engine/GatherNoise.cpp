// The gather engines over per-brick noise, compiled once here (the engine table points at them).
#include "lic/engine/Gather.h"
#include "lic/texture/Noise.h"

namespace lic {

template<typename Engine>
LicStats gatherNoiseBricks(const ConvolveJob& job, NoiseBrickSource& noise, const BrickSink& sink)
{
    return gatherBricks<Engine>(job.field, job.domain, job.layout, noise, job.settings, job.progress, sink);
}

template LicStats gatherNoiseBricks<NaiveEngine>(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);
template LicStats gatherNoiseBricks<FastEngine>(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);

} // namespace lic
