// loadField(): the single entry point that reads a bake's field in any supported format.
#include "vdbexport/io/FieldInput.h"
#include "vdbexport/io/InputFormats.h"
#include "vdbexport/io/MeshInput.h"
#include "vdbexport/io/FieldGrids.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <filesystem>
#include <fstream>

namespace fs = std::filesystem;

namespace vdbexport {

using namespace detail;

namespace {

/// The whole file, after checking that it exists, is a regular file and is not empty.
std::string readFileBytes(const std::string& path, const std::string& what)
{
    if (path.empty()) throw lic::InputError("no field file given; expected a path to " + what);
    std::error_code ec;
    const auto status = fs::status(path, ec);
    if (!fs::exists(status)) throw lic::InputError("file " + q(path) + " not found; expected " + what);
    if (fs::is_directory(status)) throw lic::InputError(q(path) + " is a directory; expected " + what);
    const auto size = fs::file_size(path, ec);
    if (ec) throw lic::InputError("cannot read " + q(path) + " (" + ec.message() + "); expected " + what);
    if (size == 0) throw lic::InputError("file " + q(path) + " is empty (0 bytes); expected " + what);
    // Dense data larger than the voxel cap as float64 Vec3 plus generous headers cannot be valid.
    const std::uintmax_t cap = kMaxDenseVoxels * 3 * 8 * 4 + (std::uintmax_t(1) << 20);
    if (size > cap)
        throw lic::InputError(q(path) + " is " + std::to_string(size) + " bytes, more than a dense field within the limit of "
                              + std::to_string(kMaxDenseVoxels) + " voxels can take");
    std::ifstream in(path, std::ios::binary);
    if (!in) throw lic::InputError("cannot open " + q(path) + " for reading (" + std::strerror(errno) + ")");
    std::string bytes(size, '\0');
    in.read(bytes.data(), static_cast<std::streamsize>(size));
    if (!in) throw lic::InputError("cannot read " + q(path) + ": read failed");
    return bytes;
}

openvdb::math::Transform::Ptr denseTransform(const openvdb::Vec3d& origin, const openvdb::Vec3d& spacing)
{
    openvdb::Mat4d m = openvdb::Mat4d::identity();
    m.setToScale(spacing);
    m.setTranslation(origin);
    return openvdb::math::Transform::createLinearTransform(m);
}

/// A grid whose voxel (i,j,k) holds element (i,j,k) of `data` (x fastest), all voxels active.
template<typename GridT, typename Get>
typename GridT::Ptr fillGrid(const std::array<std::int64_t, 3>& dims, Get&& get)
{
    using ValueT = typename GridT::ValueType;
    auto grid = GridT::create(openvdb::zeroVal<ValueT>());
    auto& tree = grid->tree();
    using LeafT = typename GridT::TreeType::LeafNodeType;
    constexpr int L = int(LeafT::DIM);
    for (std::int64_t x0 = 0; x0 < dims[0]; x0 += L)
        for (std::int64_t y0 = 0; y0 < dims[1]; y0 += L)
            for (std::int64_t z0 = 0; z0 < dims[2]; z0 += L) {
                LeafT* leaf = tree.touchLeaf(openvdb::Coord(int(x0), int(y0), int(z0)));
                for (std::int64_t x = x0; x < std::min<std::int64_t>(x0 + L, dims[0]); ++x)
                    for (std::int64_t y = y0; y < std::min<std::int64_t>(y0 + L, dims[1]); ++y)
                        for (std::int64_t z = z0; z < std::min<std::int64_t>(z0 + L, dims[2]); ++z) {
                            const std::size_t idx = std::size_t((z * dims[1] + y) * dims[0] + x);
                            leaf->setValueOn(openvdb::Coord(int(x), int(y), int(z)), get(idx));
                        }
            }
    return grid;
}

/// "npy, vti, vtk, raw": the dense formats, for messages.
std::string denseNames()
{
    std::string out;
    for (const std::string& n : inputFormatNames(InputKind::Dense)) out += (out.empty() ? "" : ", ") + n;
    return out;
}

/// "raw": the formats that take field.shape, for messages.
std::string shapeNames()
{
    std::string out;
    for (const InputFormat& f : inputFormats())
        if (f.needsShape) out += (out.empty() ? "" : ", ") + f.name;
    return out;
}

} // namespace

void denseToGrids(const DenseImage& image, const std::string& vectorName, const std::string& source, LoadedField& out)
{
    for (int a = 0; a < 3; ++a) {
        if (!(image.spacing[a] > 0) || !std::isfinite(image.spacing[a]))
            inputError(source, "voxel size " + std::to_string(image.spacing[a]) + " on axis " + std::string(1, "xyz"[a])
                                   + " is not positive; expected a voxel size > 0");
        if (!std::isfinite(image.origin[a])) inputError(source, "origin is not finite");
    }
    const DenseImage::Array* vec = nullptr;
    std::vector<const DenseImage::Array*> vectors;
    for (const auto& a : image.arrays)
        if (a.components == 3) vectors.push_back(&a);
    auto list = [&] {
        std::string s;
        for (const auto& a : image.arrays) s += (s.empty() ? "" : ", ") + a.name + " (" + std::to_string(a.components) + " components)";
        return s.empty() ? std::string("no arrays") : s;
    };
    if (!vectorName.empty()) {
        for (const auto& a : image.arrays)
            if (a.name == vectorName) vec = &a;
        if (!vec) inputError(source, "no array named " + q(vectorName) + "; the file has: " + list());
        if (vec->components != 3)
            inputError(source, "array " + q(vectorName) + " has " + std::to_string(vec->components)
                                   + " component(s); a scalar cannot be a velocity field (expected 3 components)");
    } else {
        for (const char* n : kDefaultVelocityNames)
            for (const auto* a : vectors)
                if (!vec && a->name == n) vec = a;
        if (!vec && vectors.size() == 1) vec = vectors.front();
        if (!vec && vectors.empty())
            inputError(source, "has no 3-component array to use as a velocity field; the file has: " + list()
                                   + "; expected shape (X,Y,Z,3) or (3,X,Y,Z), or a VTK array with 3 components");
        if (!vec) inputError(source, "has several vector arrays and none is named 'velocity', 'vel' or 'v': " + list()
                                         + "; pass --grid NAME to choose one");
    }
    const auto xform = denseTransform(image.origin, image.spacing);
    const float* d = vec->data.data();
    out.velocity = fillGrid<openvdb::Vec3SGrid>(image.dims, [d](std::size_t i) {
        return openvdb::Vec3s(d[3 * i], d[3 * i + 1], d[3 * i + 2]);
    });
    out.velocity->setTransform(xform->copy());
    out.velocity->setName(vec->name);
    out.velocity->setGridClass(openvdb::GRID_UNKNOWN);
    out.velocity->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    out.gridName = vec->name;
    for (const auto& a : image.arrays) {
        if (a.components != 1) continue;
        const float* s = a.data.data();
        auto g = fillGrid<openvdb::FloatGrid>(image.dims, [s](std::size_t i) { return s[i]; });
        g->setTransform(xform->copy());
        g->setName(a.name);
        out.scalars.emplace(a.name, std::move(g));
    }
}

LoadedField loadField(const FieldSpec& spec) { return loadField(spec, lic::nullProgress()); }

LoadedField loadField(const FieldSpec& spec, lic::Progress& progress)
{
    openvdb::initialize();
    LoadedField out;
    const std::string& path = spec.path;
    out.format = resolveInputFormat(path, spec.format);
    const InputFormat& format = *findInputFormat(out.format);
    if (out.format != "plot3d" && !spec.solution.empty())
        throw lic::InputError("field.solution (--solution) names a PLOT3D .q file; " + q(path) + " is not PLOT3D");
    if (format.kind == InputKind::Mesh) {
        if (spec.origin || spec.shape)
            throw lic::InputError("field.origin / field.shape (--origin, --shape) apply to dense inputs; the mesh "
                                  + q(path) + " carries its own coordinates");
        MeshOptions options;
        options.vectorName = spec.grid;
        options.voxelSize = spec.voxelSize;
        options.crop = spec.crop;
        options.time = spec.time;
        options.solution = spec.solution;
        std::uint64_t done = 0;
        options.progress = [&progress, &done](double fraction) {
            const auto units = std::uint64_t(std::clamp(fraction, 0.0, 1.0) * 1000);
            if (units > done) progress.advance(units - done);
            done = std::max(done, units);
            return !progress.wasInterrupted();
        };
        progress.begin("resampling the mesh", 1000);
        out = loadMesh(path, out.format, options, spec.nanPolicy);
        progress.end();
    } else if (spec.time) {
        throw lic::InputError("field.time (--time) picks a time of a series (.pvd, an OpenFOAM case); " + q(path)
                              + " is a single field");
    } else if (format.kind == InputKind::Grid) {
        if (spec.voxelSize || spec.origin)
            throw lic::InputError("field.voxel_size / field.origin (--voxel-size, --origin) apply to dense inputs ("
                                  + denseNames() + "); " + format.description
                                  + " carries its own transform (use --resample to change the voxel size)");
        out.velocity = readVelocityGrid(path, spec.grid, &out.gridName);
        out.scalars = readScalarGrids(path);
    } else {
        const std::string& what = format.description;
        if (format.needsShape && !spec.shape)
            throw lic::InputError(out.format + " field " + q(path)
                                  + " needs its shape: pass --shape X,Y,Z (and --dtype float32|float64)");
        if (!format.needsShape && spec.shape)
            throw lic::InputError("field.shape (--shape) applies to " + shapeNames() + " input only; " + q(path) + " is "
                                  + what + " and declares its own shape");
        const std::string bytes = readFileBytes(path, what);
        DenseImage img = format.parse(bytes, spec, path);
        if (spec.voxelSize) img.spacing = openvdb::Vec3d(*spec.voxelSize);
        if (spec.origin) img.origin = openvdb::Vec3d((*spec.origin)[0], (*spec.origin)[1], (*spec.origin)[2]);
        denseToGrids(img, spec.grid, path, out);
    }
    prepareField(spec, path, out);
    return out;
}

} // namespace vdbexport
