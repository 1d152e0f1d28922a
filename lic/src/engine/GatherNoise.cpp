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
    const openvdb::CoordBBox& fb = job.field.indexBBox();
    const int K = job.domain.upsample();
    const openvdb::Coord lo(fb.min()[0] * K, fb.min()[1] * K, fb.min()[2] * K);
    const openvdb::Coord hi(fb.max()[0] * K + K - 1, fb.max()[1] * K + K - 1, fb.max()[2] * K + K - 1);
    noise.clipTo(openvdb::CoordBBox(lo, hi).expandBy(1));
    return gatherBricks<Engine>(job.field, job.domain, job.layout, noise, job.settings, job.progress, sink);
}

template LicStats gatherNoiseBricks<NaiveEngine>(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);
template LicStats gatherNoiseBricks<FastEngine>(const ConvolveJob&, NoiseBrickSource&, const BrickSink&);

} // namespace lic
