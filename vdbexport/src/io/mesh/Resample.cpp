// A checked mesh resampled onto the VDB lattice: cell data to points, VTK's probe
// (vtkResampleToImage) at every lattice point, and the samples inside the mesh as grids.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <openvdb/openvdb.h>

#include <vtkCallbackCommand.h>
#include <vtkCellData.h>
#include <vtkCellDataToPointData.h>
#include <vtkCommand.h>
#include <vtkDataArray.h>
#include <vtkImageData.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkResampleToImage.h>

#include <algorithm>
#include <cmath>
#include <sstream>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace {

/// Cell arrays without a point array of the same name averaged to the points (VTK's
/// vtkCellDataToPointData), per block; point arrays kept as they are (an OpenFOAM reader's point
/// data already use the boundary patches' values).
vtkSmartPointer<vtkDataObject> withPointData(const Mesh& m, bool& averaged)
{
    averaged = false;
    auto needsAveraging = [](vtkDataSet* ds) {
        for (int a = 0; a < ds->GetCellData()->GetNumberOfArrays(); ++a) {
            const char* name = ds->GetCellData()->GetArrayName(a);
            if (!internalArray(name) && !ds->GetPointData()->GetArray(name)) return true;
        }
        return false;
    };
    for (const auto& ds : m.leaves) averaged = averaged || needsAveraging(ds);
    if (!averaged && m.leaves.size() == 1) return m.leaves.front().GetPointer();
    auto blocks = vtkSmartPointer<vtkMultiBlockDataSet>::New();
    unsigned n = 0;
    for (const auto& ds : m.leaves) {
        if (!needsAveraging(ds)) {
            blocks->SetBlock(n++, ds);
            continue;
        }
        vtkNew<vtkCellDataToPointData> c2p;
        c2p->SetInputData(ds);
        c2p->PassCellDataOff();
        c2p->ProcessAllArraysOn();
        c2p->Update();
        vtkSmartPointer<vtkDataSet> out = c2p->GetOutput();
        for (int a = 0; a < ds->GetPointData()->GetNumberOfArrays(); ++a)
            out->GetPointData()->AddArray(ds->GetPointData()->GetAbstractArray(a)); // the file's own win
        blocks->SetBlock(n++, out);
    }
    return blocks;
}

struct ProgressClient
{
    const std::function<bool(double)>* callback;
    bool cancelled = false;
};

void onProgress(vtkObject* caller, unsigned long, void* client, void* data)
{
    auto* c = static_cast<ProgressClient*>(client);
    if (!c->callback || !*c->callback || !data || c->cancelled) return;
    if (!(*c->callback)(*static_cast<double*>(data))) {
        c->cancelled = true;
        if (auto* algorithm = vtkAlgorithm::SafeDownCast(caller)) algorithm->SetAbortExecute(1);
    }
}


/// The lattice the mesh is resampled onto: voxel (0,0,0) at the low corner of the (cropped)
/// bounds, `h` apart.
struct Lattice
{
    std::array<std::array<double, 3>, 2> box;
    double h = 0;
    std::array<int, 3> dims{};
};

Lattice chooseLattice(const Mesh& m, const MeshOptions& options, const std::string& path)
{
    Lattice l;
    l.box = boundsOf(m.leaves);
    if (options.crop) {
        for (int a = 0; a < 3; ++a) {
            l.box[0][a] = std::max(l.box[0][a], (*options.crop)[0][a]);
            l.box[1][a] = std::min(l.box[1][a], (*options.crop)[1][a]);
            if (!(l.box[1][a] > l.box[0][a]))
                detail::inputError(path, std::string("the crop box misses the mesh along ") + "xyz"[a]);
        }
    }
    l.h = options.voxelSize ? *options.voxelSize : medianCellSize(m.leaves);
    if (!(l.h > 0) || !std::isfinite(l.h)) detail::inputError(path, "has degenerate cells (zero size): pass --voxel-size");
    double voxels = 1;
    for (int a = 0; a < 3; ++a) {
        const double n = std::floor((l.box[1][a] - l.box[0][a]) / l.h + 1e-9) + 1;
        voxels *= n;
        l.dims[a] = n < 2e9 ? int(n) : 0;
    }
    const double maxVoxels = double(std::min<std::uint64_t>(options.maxVoxels, kMaxDenseVoxels));
    if (voxels > maxVoxels || l.dims[0] == 0 || l.dims[1] == 0 || l.dims[2] == 0) {
        const double hMin = l.h * std::cbrt(voxels / maxVoxels) * 1.01;
        detail::inputError(path, "resampling at voxel size " + num(l.h) + " makes " + num(voxels)
                                 + " voxels, more than the limit of " + num(maxVoxels) + "; pass --voxel-size "
                                 + num(hMin) + " or larger, or --crop a smaller box");
    }
    return l;
}

/// VTK's probe of `input` at every lattice point (vtkResampleToImage), with progress.
vtkSmartPointer<vtkImageData> probe(vtkDataObject* input, const Lattice& l, const MeshOptions& options,
                                    const std::string& path, const std::string& format, std::string& maskName)
{
    vtkNew<vtkResampleToImage> resample;
    resample->SetInputDataObject(input);
    resample->UseInputBoundsOff();
    resample->SetSamplingBounds(l.box[0][0], l.box[0][0] + (l.dims[0] - 1) * l.h, l.box[0][1],
                                l.box[0][1] + (l.dims[1] - 1) * l.h, l.box[0][2], l.box[0][2] + (l.dims[2] - 1) * l.h);
    resample->SetSamplingDimensions(l.dims[0], l.dims[1], l.dims[2]);
    ProgressClient client{&options.progress};
    vtkNew<vtkCallbackCommand> progress;
    progress->SetCallback(onProgress);
    progress->SetClientData(&client);
    resample->AddObserver(vtkCommand::ProgressEvent, progress);
    runChecked(resample, path, describeFormat(format), [&] { resample->Update(); });
    if (client.cancelled) throw lic::Cancelled();
    maskName = resample->GetMaskArrayName();
    vtkSmartPointer<vtkImageData> image = resample->GetOutput();
    return image;
}

/// The probed values inside the mesh as grids: the velocity and one float grid per scalar array.
/// @return the number of active voxels.
std::uint64_t gridsFromImage(vtkImageData* image, const std::string& maskName, const Lattice& l,
                             const std::string& velocityName, const std::string& path, LoadedField& out)
{
    vtkDataArray* mask = image->GetPointData()->GetArray(maskName.c_str());
    vtkDataArray* vel = image->GetPointData()->GetArray(velocityName.c_str());
    if (!mask || !vel) detail::inputError(path, "VTK's resampling lost the array " + q(velocityName));
    openvdb::Mat4d mat = openvdb::Mat4d::identity();
    mat.setToScale(openvdb::Vec3d(l.h));
    mat.setTranslation(openvdb::Vec3d(l.box[0][0], l.box[0][1], l.box[0][2]));
    const auto xform = openvdb::math::Transform::createLinearTransform(mat);
    out.velocity = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    out.velocity->setTransform(xform->copy());
    std::vector<std::pair<vtkDataArray*, openvdb::FloatGrid::Ptr>> scalars;
    for (int a = 0; a < image->GetPointData()->GetNumberOfArrays(); ++a) {
        vtkDataArray* arr = image->GetPointData()->GetArray(a);
        if (!arr || arr->GetNumberOfComponents() != 1 || internalArray(arr->GetName())) continue;
        auto g = openvdb::FloatGrid::create(0.0f);
        g->setTransform(xform->copy());
        g->setName(arr->GetName());
        scalars.emplace_back(arr, g);
    }
    auto vacc = out.velocity->getAccessor();
    std::vector<openvdb::FloatGrid::Accessor> saccs;
    for (auto& [arr, g] : scalars) saccs.push_back(g->getAccessor());
    std::uint64_t active = 0;
    const vtkIdType nx = l.dims[0], ny = l.dims[1];
    for (int k = 0; k < l.dims[2]; ++k)
        for (int j = 0; j < l.dims[1]; ++j)
            for (int i = 0; i < l.dims[0]; ++i) {
                const vtkIdType id = i + nx * (j + ny * vtkIdType(k));
                if (mask->GetComponent(id, 0) == 0) continue;
                const openvdb::Coord ijk(i, j, k);
                vacc.setValueOn(ijk, openvdb::Vec3s(float(vel->GetComponent(id, 0)), float(vel->GetComponent(id, 1)),
                                                    float(vel->GetComponent(id, 2))));
                for (std::size_t s = 0; s < scalars.size(); ++s)
                    saccs[s].setValueOn(ijk, float(scalars[s].first->GetComponent(id, 0)));
                ++active;
            }
    for (auto& [arr, g] : scalars) {
        g->pruneGrid();
        out.scalars.emplace(arr->GetName(), g);
    }
    return active;
}


} // namespace


LoadedField loadMesh(const std::string& path, const std::string& format, const MeshOptions& options,
                     const std::string& nanPolicy)
{
    openvdb::initialize();
    Mesh m = readMesh(path, format, options);
    const std::string velocityName = chooseVelocity(m.leaves, options.vectorName, path);
    LoadedField out;
    out.format = format;
    out.nonFiniteReplaced = checkVelocityValues(m.leaves, velocityName, nanPolicy, path);
    const Lattice l = chooseLattice(m, options, path);
    bool averaged = false;
    const vtkSmartPointer<vtkDataObject> input = withPointData(m, averaged);
    std::string maskName;
    const vtkSmartPointer<vtkImageData> image = probe(input, l, options, path, format, maskName);
    const std::uint64_t active = gridsFromImage(image, maskName, l, velocityName, path, out);
    if (active == 0)
        detail::inputError(path, "no voxel centre at voxel size " + num(l.h)
                                 + " lies inside a volume cell of the mesh (a surface mesh, or cells smaller than a voxel "
                                   "and between voxel centres: pass a smaller --voxel-size)");

    out.velocity->setName(velocityName);
    out.velocity->setGridClass(openvdb::GRID_UNKNOWN);
    out.velocity->setVectorType(openvdb::VEC_CONTRAVARIANT_RELATIVE);
    out.gridName = velocityName;
    auto tag = [&](openvdb::GridBase& g, const std::string& array) {
        g.insertMeta("source", openvdb::StringMetadata(path));
        g.insertMeta("source_format", openvdb::StringMetadata(format));
        g.insertMeta("source_array", openvdb::StringMetadata(array));
        if (m.time) g.insertMeta("source_time", openvdb::DoubleMetadata(*m.time));
    };
    tag(*out.velocity, velocityName);
    for (auto& [name, g] : out.scalars) tag(*g, name);

    std::uint64_t cells = 0;
    for (const auto& ds : m.leaves) cells += std::uint64_t(ds->GetNumberOfCells());
    std::ostringstream note;
    note << "resampled " << cells << " cells" << (m.leaves.size() > 1 ? " in " + std::to_string(m.leaves.size()) + " blocks" : "")
         << (m.time ? " at time " + num(*m.time) : "") << " onto " << l.dims[0] << "x" << l.dims[1] << "x" << l.dims[2]
         << " voxels of size " << num(l.h) << (options.voxelSize ? "" : " (the median cell size; --voxel-size to change)")
         << ": " << active << " inside the mesh";
    out.notes.push_back(note.str());
    if (averaged) out.notes.push_back("cell data were averaged to the mesh points, then interpolated within cells");
    if (out.nonFiniteReplaced)
        out.notes.push_back("replaced " + std::to_string(out.nonFiniteReplaced) + " NaN/Inf velocity components with 0");
    return out;
}

} // namespace vdbexport::mesh_module
