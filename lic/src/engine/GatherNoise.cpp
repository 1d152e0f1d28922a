// The gather engines over per-brick noise, compiled once here (the engine table points at them).
#include "lic/engine/Gather.h"
#include "lic/texture/Noise.h"

namespace lic {

template<typename Engine>
LicStats gatherNoiseBricks(const ConvolveJob& job, NoiseBrickSource& noise, const BrickSink& sink)
{
    // Samples stay in the field's index box grown by half a voxel, i.e. output index
    // [K·min − ½, K·(max + 1) − ½] (output voxel j's centre is at field index (j + ½)/K − ½): their
    // lookups read voxels K·min − 1 … K·(max + 1), which a texture over the field's output voxels
    // holds (NoiseTexture keeps one voxel around its box). One more voxel to spare.
    noise.clipTo(OutputDomain::outputBox(job.field.indexBBox(), job.domain.upsample()).expandBy(1));
    return gatherBricks<Engine>(job.field, job.domain, job.layout, noise, job.settings, job.progress, sink);
}

template LicStats gatherNoiseBricks<NaiveEngine>(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);
template LicStats gatherNoiseBricks<FastEngine>(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);

} // namespace lic
