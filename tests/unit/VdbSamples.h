// Sample .vdb files of the kinds users pass around, for the structural-check tests, the mutation
// tests and the fuzz corpus (tests/fuzz/make_vdb_samples.cpp): our own field and bake, a
// mantaflow-style cache (staggered half-float velocity, blosc and zip), Houdini-style split
// vel.x/.y/.z, every value type OpenVDB registers with tiles, instances and the mask-compression
// cases, uncompressed, and a streamed file without grid offsets.
#pragma once

#include <filesystem>
#include <string>
#include <vector>

namespace vdb_samples {

/// Writes the samples into `dir` (res³ voxels each) and returns their paths. Every file is
/// intact: checkVdbStructure accepts it and OpenVDB reads it. (VdbSamples.cpp)
std::vector<std::string> writeVdbSamples(const std::filesystem::path& dir, int res = 16);

} // namespace vdb_samples
