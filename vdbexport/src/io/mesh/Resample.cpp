// A checked mesh resampled onto the VDB lattice. The lattice covers the (cropped) bounds, its upper
// faces included, with a voxel to spare on every side; VTK's probe (vtkResampleToImage) tells which
// lattice points lie inside a cell: those are active, and so is a one-voxel band around them
// (every corner of a lattice cell that touches the fluid), so that trilinear sampling anywhere in
// the fluid finds its 8 corners active. Values: cell data by a weighted least-squares linear fit over the nearest
// cell centres, limited to the neighbours' range (not VTK's cell-to-point averaging, which smears
// coarse meshes; nor the OpenFOAM reader's boundary point values, which made the T-junction's fit
// worse: docs/performance.md); point data by VTK's probe (trilinear within the cells) inside, and
// the same fit over the nearest mesh points in the band.
#include "io/mesh/Mesh.h"

#include "io/DenseCommon.h"

#include <lic/util/Error.h>

#include <openvdb/openvdb.h>

#include <tbb/blocked_range.h>
#include <tbb/enumerable_thread_specific.h>
#include <tbb/parallel_for.h>

#include <vtkCallbackCommand.h>
#include <vtkCellData.h>
#include <vtkCommand.h>
#include <vtkDataArray.h>
#include <vtkIdList.h>
#include <vtkImageData.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkPolyData.h>
#include <vtkResampleToImage.h>
#include <vtkStaticPointLocator.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <sstream>

namespace fs = std::filesystem;

namespace vdbexport::mesh_module {

using detail::q;

namespace {

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

/// The default voxel size's budget: at most this many lattice points (and options.maxVoxels).
constexpr double kDefaultVoxelBudget = 16.0 * 1024 * 1024;

/// The lattice the mesh is resampled onto: voxel (0,0,0) one voxel below the low corner of the
/// (cropped) bounds, `h` apart, reaching at least one voxel past the upper corner.
struct Lattice
{
    std::array<std::array<double, 3>, 2> box;
    std::array<double, 3> origin{};
    double h = 0;
    std::array<int, 3> dims{};  ///< the whole lattice, with the ring of one voxel around the box
    std::array<int, 3> probed{}; ///< the part VTK probes: the box's points (dims - 2)
    std::string rule; ///< how the default voxel size was chosen ("" when given)
};

double voxelCount(const std::array<std::array<double, 3>, 2>& box, double h)
{
    double voxels = 1;
    for (int a = 0; a < 3; ++a) voxels *= std::ceil((box[1][a] - box[0][a]) / h - 1e-9) + 3;
    return voxels;
}

/// The default voxel size for LIC: half the 10th percentile of the cell sizes (so the smaller
/// cells, which are where the passages are narrow and the walls near, get two voxels each), at most
/// a quarter of the smallest extent of the box (five lattice points across its thinnest side);
/// then, if that makes more than min(16 Mi, maxVoxels) lattice points, the smallest size that fits.
double defaultVoxelSize(const Mesh& m, const std::array<std::array<double, 3>, 2>& box, double maxVoxels,
                        std::string& rule)
{
    const std::vector<double> sizes = cellSizes(m.leaves);
    if (sizes.empty()) return 0;
    const double p10 = sizes[sizes.size() / 10];
    double h = 0.5 * p10;
    rule = "half the 10th percentile of the cell sizes";
    double minExtent = HUGE_VAL;
    for (int a = 0; a < 3; ++a)
        if (box[1][a] > box[0][a]) minExtent = std::min(minExtent, box[1][a] - box[0][a]);
    if (std::isfinite(minExtent) && minExtent / 4 < h) {
        h = minExtent / 4;
        rule = "a quarter of the box's smallest extent";
    }
    const double budget = std::min(kDefaultVoxelBudget, maxVoxels);
    for (int i = 0; i < 64 && voxelCount(box, h) > budget; ++i) {
        h *= std::max(1.01, std::cbrt(voxelCount(box, h) / budget));
        rule = "the smallest size within " + num(budget) + " voxels";
    }
    return h;
}

/// The box the lattice covers: the mesh's bounds, cropped.
std::array<std::array<double, 3>, 2> latticeBox(const Mesh& m, const MeshOptions& options, const std::string& path)
{
    std::array<std::array<double, 3>, 2> box = boundsOf(m.leaves);
    if (options.crop) {
        for (int a = 0; a < 3; ++a) {
            box[0][a] = std::max(box[0][a], (*options.crop)[0][a]);
            box[1][a] = std::min(box[1][a], (*options.crop)[1][a]);
            if (!(box[1][a] > box[0][a]))
                detail::inputError(path, std::string("the crop box misses the mesh along ") + "xyz"[a]);
        }
    }
    return box;
}

double maxLatticeVoxels(const MeshOptions& options)
{
    return double(std::min<std::uint64_t>(options.maxVoxels, kMaxDenseVoxels));
}

Lattice chooseLattice(const Mesh& m, const MeshOptions& options, const std::string& path)
{
    Lattice l;
    l.box = latticeBox(m, options, path);
    const double maxVoxels = maxLatticeVoxels(options);
    l.h = options.voxelSize ? *options.voxelSize : defaultVoxelSize(m, l.box, maxVoxels, l.rule);
    if (!(l.h > 0) || !std::isfinite(l.h)) detail::inputError(path, "has degenerate cells (zero size): pass --voxel-size");
    double voxels = 1;
    for (int a = 0; a < 3; ++a) {
        // One voxel below the low corner, the upper corner reached (never dropped when
        // extent / h rounds just under an integer), and one voxel past it: the band's room.
        const double n = std::ceil((l.box[1][a] - l.box[0][a]) / l.h - 1e-9) + 3;
        voxels *= n;
        l.dims[a] = n < 2e9 ? int(n) : 0;
        l.probed[a] = l.dims[a] - 2;
        l.origin[a] = l.box[0][a] - l.h;
    }
    if (voxels > maxVoxels || l.dims[0] == 0 || l.dims[1] == 0 || l.dims[2] == 0) {
        const double hMin = l.h * std::cbrt(voxels / maxVoxels) * 1.01;
        detail::inputError(path, "resampling at voxel size " + num(l.h) + " makes " + num(voxels)
                                 + " voxels, more than the limit of " + num(maxVoxels) + "; pass --voxel-size "
                                 + num(hMin) + " or larger, or --crop a smaller box");
    }
    return l;
}

/// VTK's probe of the mesh at every lattice point (vtkResampleToImage), with progress.
vtkSmartPointer<vtkImageData> probe(const Mesh& m, const Lattice& l, const MeshOptions& options,
                                    const std::string& path, const std::string& format, std::string& maskName)
{
    vtkSmartPointer<vtkDataObject> input;
    if (m.leaves.size() == 1) {
        input = m.leaves.front().GetPointer();
    } else {
        auto blocks = vtkSmartPointer<vtkMultiBlockDataSet>::New();
        for (unsigned i = 0; i < m.leaves.size(); ++i) blocks->SetBlock(i, m.leaves[i]);
        input = blocks;
    }
    vtkNew<vtkResampleToImage> resample;
    resample->SetInputDataObject(input);
    resample->UseInputBoundsOff();
    // The box's points only, from its low corner exactly (the ring around it is outside the mesh).
    // A last point past the upper corner by a rounding error (extent / h just under an integer) is
    // probed on the corner: VTK's probe would find it outside by that error, and the face lost.
    double bounds[6];
    for (int a = 0; a < 3; ++a) {
        bounds[2 * a] = l.box[0][a];
        bounds[2 * a + 1] = l.box[0][a] + (l.probed[a] - 1) * l.h;
        if (bounds[2 * a + 1] > l.box[1][a] && bounds[2 * a + 1] - l.box[1][a] < 1e-3 * l.h)
            bounds[2 * a + 1] = l.box[1][a];
    }
    resample->SetSamplingBounds(bounds);
    resample->SetSamplingDimensions(l.probed[0], l.probed[1], l.probed[2]);
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

// ---- the active voxels -----------------------------------------------------------------------

/// The active lattice points: those inside a cell (the probe's mask) and every corner of a lattice
/// cell that has such a point as a corner or holds a mesh point or cell centre (a passage thinner
/// than a voxel). `inside[id]` keeps which were inside.
std::vector<char> activeLattice(const Mesh& m, const Lattice& l, vtkDataArray* mask, std::vector<char>& inside)
{
    const vtkIdType nx = l.dims[0], ny = l.dims[1], nz = l.dims[2], n = nx * ny * nz;
    inside.assign(std::size_t(n), 0);
    const vtkIdType px = l.probed[0], py = l.probed[1];
    for (vtkIdType k = 1; k + 1 < nz; ++k)
        for (vtkIdType j = 1; j + 1 < ny; ++j)
            for (vtkIdType i = 1; i + 1 < nx; ++i)
                inside[std::size_t(i + nx * (j + ny * k))] =
                    mask->GetComponent((i - 1) + px * ((j - 1) + py * (k - 1)), 0) != 0;
    std::vector<char> cellTouches(std::size_t(n), 0); // lattice cell (i,j,k): [i,i+1]×[j,j+1]×[k,k+1]
    auto index = [&](vtkIdType i, vtkIdType j, vtkIdType k) { return std::size_t(i + nx * (j + ny * k)); };
    for (vtkIdType k = 0; k < nz; ++k)
        for (vtkIdType j = 0; j < ny; ++j)
            for (vtkIdType i = 0; i < nx; ++i) {
                if (!inside[index(i, j, k)]) continue;
                for (vtkIdType c = std::max<vtkIdType>(0, k - 1); c <= k && c < nz - 1; ++c)
                    for (vtkIdType b = std::max<vtkIdType>(0, j - 1); b <= j && b < ny - 1; ++b)
                        for (vtkIdType a = std::max<vtkIdType>(0, i - 1); a <= i && a < nx - 1; ++a)
                            cellTouches[index(a, b, c)] = 1;
            }
    auto touch = [&](const double* p) {
        vtkIdType ijk[3];
        for (int a = 0; a < 3; ++a) {
            const double x = std::floor((p[a] - l.origin[a]) / l.h);
            if (!(x >= 0 && x < double(l.dims[a] - 1))) return;
            ijk[a] = vtkIdType(x);
        }
        cellTouches[index(ijk[0], ijk[1], ijk[2])] = 1;
    };
    vtkNew<vtkIdList> ids;
    for (const auto& ds : m.leaves) {
        double p[3];
        std::vector<char> used(std::size_t(ds->GetNumberOfPoints()), 0); // points of no cell do not count
        for (vtkIdType c = 0; c < ds->GetNumberOfCells(); ++c) {
            ds->GetCellPoints(c, ids);
            for (vtkIdType i = 0; i < ids->GetNumberOfIds(); ++i) used[std::size_t(ids->GetId(i))] = 1;
        }
        for (vtkIdType i = 0; i < ds->GetNumberOfPoints(); ++i) {
            if (!used[std::size_t(i)]) continue;
            ds->GetPoint(i, p);
            touch(p);
        }
        for (vtkIdType c = 0; c < ds->GetNumberOfCells(); ++c) {
            double b[6];
            ds->GetCellBounds(c, b);
            const double centre[3] = {0.5 * (b[0] + b[1]), 0.5 * (b[2] + b[3]), 0.5 * (b[4] + b[5])};
            touch(centre);
        }
    }
    std::vector<char> active(std::size_t(n), 0);
    for (vtkIdType k = 0; k + 1 < nz; ++k)
        for (vtkIdType j = 0; j + 1 < ny; ++j)
            for (vtkIdType i = 0; i + 1 < nx; ++i) {
                if (!cellTouches[index(i, j, k)]) continue;
                for (int c = 0; c < 2; ++c)
                    for (int b = 0; b < 2; ++b)
                        for (int a = 0; a < 2; ++a) active[index(i + a, j + b, k + c)] = 1;
            }
    return active;
}

// ---- the values --------------------------------------------------------------------------------

/// Where an array's values come from: source points (cell centres, or mesh points), each
/// naming the leaf, the id, and whether it is a point of that leaf (else a cell).
struct Sources
{
    vtkSmartPointer<vtkPoints> points = vtkSmartPointer<vtkPoints>::New();
    std::vector<std::uint32_t> leaf;
    std::vector<vtkIdType> id;
    std::vector<char> onPoints;
    vtkSmartPointer<vtkStaticPointLocator> locator;
    std::vector<std::string> arrays; ///< the arrays read from these sources
};

/// How an array is stored in a leaf: 'c' on the cells (whatever the points have: the OpenFOAM
/// reader's point values are its own averages of the cells), 'p' on the points only, '-' absent.
char arrayKind(vtkDataSet* ds, const std::string& name)
{
    if (ds->GetCellData()->GetArray(name.c_str())) return 'c';
    return ds->GetPointData()->GetArray(name.c_str()) ? 'p' : '-';
}

Sources makeSources(const Mesh& m, const std::string& kinds)
{
    Sources s;
    vtkNew<vtkIdList> ids;
    for (std::uint32_t b = 0; b < m.leaves.size(); ++b) {
        vtkDataSet* ds = m.leaves[b];
        auto add = [&](const double* p, vtkIdType id, bool onPoints) {
            s.points->InsertNextPoint(p);
            s.leaf.push_back(b);
            s.id.push_back(id);
            s.onPoints.push_back(onPoints);
        };
        double p[3];
        if (kinds[b] == 'p') {
            for (vtkIdType i = 0; i < ds->GetNumberOfPoints(); ++i) {
                ds->GetPoint(i, p);
                add(p, i, true);
            }
            continue;
        }
        for (vtkIdType c = 0; c < ds->GetNumberOfCells(); ++c) { // the centre: the mean of the cell's points
            ds->GetCellPoints(c, ids);
            double centre[3] = {0, 0, 0};
            const vtkIdType k = ids->GetNumberOfIds();
            if (k == 0) continue;
            for (vtkIdType i = 0; i < k; ++i) {
                ds->GetPoint(ids->GetId(i), p);
                for (int a = 0; a < 3; ++a) centre[a] += p[a] / double(k);
            }
            add(centre, c, false);
        }
    }
    auto polys = vtkSmartPointer<vtkPolyData>::New();
    polys->SetPoints(s.points);
    s.locator = vtkSmartPointer<vtkStaticPointLocator>::New();
    s.locator->SetDataSet(polys);
    s.locator->BuildLocator();
    return s;
}

/// The number of sources each fit uses (measured on three OpenFOAM tutorials against 12 and 20,
/// and inverse-distance weights over 4, 8 and 12: docs/performance.md).
constexpr int kNeighbours = 8;

/// The weighted least-squares fit of a + g·(x - p) over the sources `ids` around p (weights 1 /
/// (d² + (h/100)²), a small ridge on g so that flat or collinear neighbourhoods still fit): the
/// weights c_j with a = Σ c_j f_j. False where the fit is singular (then inverse-distance weights).
void fitWeights(const Sources& s, const double* p, vtkIdList* ids, double h, std::vector<double>& c)
{
    const vtkIdType n = ids->GetNumberOfIds();
    c.assign(std::size_t(n), 0.0);
    double A[4][4] = {};
    std::vector<std::array<double, 4>> rows(static_cast<std::size_t>(n));
    std::vector<double> w(static_cast<std::size_t>(n), 0.0);
    double wsum = 0, spread = 0;
    for (vtkIdType j = 0; j < n; ++j) {
        double x[3];
        s.points->GetPoint(ids->GetId(j), x);
        const double d[3] = {x[0] - p[0], x[1] - p[1], x[2] - p[2]};
        const double d2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2];
        w[std::size_t(j)] = 1.0 / (d2 + 1e-4 * h * h);
        rows[std::size_t(j)] = {1.0, d[0], d[1], d[2]};
        wsum += w[std::size_t(j)];
        spread += w[std::size_t(j)] * d2;
        for (int r = 0; r < 4; ++r)
            for (int q = 0; q < 4; ++q) A[r][q] += w[std::size_t(j)] * rows[std::size_t(j)][std::size_t(r)] * rows[std::size_t(j)][std::size_t(q)];
    }
    const double ridge = 1e-3 * spread / 3 + 1e-12 * wsum * h * h;
    for (int r = 1; r < 4; ++r) A[r][r] += ridge;
    // a = e0ᵀ A⁻¹ Σ w_j row_j f_j: solve A z = e0 (A is symmetric), then c_j = w_j row_j·z.
    double M[4][5];
    for (int r = 0; r < 4; ++r) {
        for (int q = 0; q < 4; ++q) M[r][q] = A[r][q];
        M[r][4] = r == 0 ? 1.0 : 0.0;
    }
    bool ok = true;
    for (int col = 0; col < 4 && ok; ++col) {
        int piv = col;
        for (int r = col + 1; r < 4; ++r)
            if (std::abs(M[r][col]) > std::abs(M[piv][col])) piv = r;
        if (!(std::abs(M[piv][col]) > 1e-300)) {
            ok = false;
            break;
        }
        for (int q = 0; q < 5; ++q) std::swap(M[col][q], M[piv][q]);
        for (int r = 0; r < 4; ++r) {
            if (r == col) continue;
            const double f = M[r][col] / M[col][col];
            for (int q = col; q < 5; ++q) M[r][q] -= f * M[col][q];
        }
    }
    if (ok) {
        double z[4];
        for (int r = 0; r < 4; ++r) z[r] = M[r][4] / M[r][r];
        for (vtkIdType j = 0; j < n; ++j) {
            const auto& row = rows[std::size_t(j)];
            c[std::size_t(j)] = w[std::size_t(j)] * (row[0] * z[0] + row[1] * z[1] + row[2] * z[2] + row[3] * z[3]);
        }
        if (std::all_of(c.begin(), c.end(), [](double v) { return std::isfinite(v); })) return;
    }
    for (vtkIdType j = 0; j < n; ++j) c[std::size_t(j)] = w[std::size_t(j)] / wsum;
}

/// One output array: its name, components, and where its values are read.
struct Output
{
    std::string name;
    int components = 1;
    std::vector<vtkDataArray*> cells, points; ///< per leaf (null where absent)
    vtkDataArray* probed = nullptr;            ///< the probe's values (point data only)
    bool fromPoints = false;                   ///< point data in every leaf: the probe inside
    std::vector<float> values;                 ///< per active point, `components` each
};

/// The fitted values of the outputs reading `s` at the active lattice points `points` (lattice
/// ids), each limited to the range of the values it was fitted from.
void fitValues(const Sources& s, std::vector<Output*>& outs, const std::vector<vtkIdType>& lattice,
               const std::vector<std::size_t>& slots, const Lattice& l)
{
    struct Scratch
    {
        vtkSmartPointer<vtkIdList> ids = vtkSmartPointer<vtkIdList>::New();
        std::vector<double> c;
    };
    tbb::enumerable_thread_specific<Scratch> scratch;
    const vtkIdType nx = l.dims[0], ny = l.dims[1];
    const int neighbours = int(std::min<vtkIdType>(kNeighbours, s.points->GetNumberOfPoints()));
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, lattice.size(), 256), [&](const tbb::blocked_range<std::size_t>& r) {
        Scratch& sc = scratch.local();
        for (std::size_t i = r.begin(); i != r.end(); ++i) {
            const vtkIdType id = lattice[i];
            const double p[3] = {l.origin[0] + double(id % nx) * l.h, l.origin[1] + double((id / nx) % ny) * l.h,
                                 l.origin[2] + double(id / (nx * ny)) * l.h};
            s.locator->FindClosestNPoints(neighbours, p, sc.ids);
            fitWeights(s, p, sc.ids, l.h, sc.c);
            for (Output* o : outs)
                for (int comp = 0; comp < o->components; ++comp) {
                    double v = 0, lo = HUGE_VAL, hi = -HUGE_VAL;
                    for (vtkIdType j = 0; j < sc.ids->GetNumberOfIds(); ++j) {
                        const vtkIdType src = sc.ids->GetId(j);
                        const std::size_t b = s.leaf[std::size_t(src)];
                        vtkDataArray* a = s.onPoints[std::size_t(src)] ? o->points[b] : o->cells[b];
                        const double f = a->GetComponent(s.id[std::size_t(src)], comp);
                        v += sc.c[std::size_t(j)] * f;
                        lo = std::min(lo, f);
                        hi = std::max(hi, f);
                    }
                    o->values[slots[i] * std::size_t(o->components) + std::size_t(comp)] = float(std::clamp(v, lo, hi));
                }
        }
    });
}

/// The outputs: the velocity, then every one-component array of the mesh (by name, sorted) that
/// every leaf holds with that many components.
std::vector<Output> outputsOf(const Mesh& m, vtkImageData* image, const std::string& velocityName, const std::string& path)
{
    std::vector<Output> outs;
    auto addOutput = [&](const std::string& name, int components) {
        Output o;
        o.name = name;
        o.components = components;
        bool allPoints = true;
        for (const auto& ds : m.leaves) {
            vtkDataArray* c = ds->GetCellData()->GetArray(name.c_str());
            vtkDataArray* p = ds->GetPointData()->GetArray(name.c_str());
            if (c && c->GetNumberOfComponents() != components) c = nullptr;
            if (p && p->GetNumberOfComponents() != components) p = nullptr;
            if (!c && !p) return;
            o.cells.push_back(c);
            o.points.push_back(p);
            allPoints = allPoints && !c;
        }
        o.fromPoints = allPoints;
        o.probed = image->GetPointData()->GetArray(name.c_str());
        if (o.fromPoints && (!o.probed || o.probed->GetNumberOfComponents() != components)) return;
        outs.push_back(std::move(o));
    };
    addOutput(velocityName, 3);
    if (outs.empty()) detail::inputError(path, "VTK's resampling lost the array " + q(velocityName));
    {
        std::vector<std::string> names;
        for (auto* attrs : {static_cast<vtkDataSetAttributes*>(m.leaves.front()->GetCellData()),
                            static_cast<vtkDataSetAttributes*>(m.leaves.front()->GetPointData())})
            for (int a = 0; a < attrs->GetNumberOfArrays(); ++a)
                if (vtkDataArray* arr = attrs->GetArray(a); arr && arr->GetName() && arr->GetNumberOfComponents() == 1
                                                            && !internalArray(arr->GetName()))
                    names.push_back(arr->GetName());
        std::sort(names.begin(), names.end());
        names.erase(std::unique(names.begin(), names.end()), names.end());
        for (const auto& n : names) addOutput(n, 1);
    }

    return outs;
}

} // namespace

double defaultLatticeVoxelSize(const Mesh& m, const MeshOptions& options, const std::string& path, std::string& rule)
{
    return defaultVoxelSize(m, latticeBox(m, options, path), maxLatticeVoxels(options), rule);
}

LoadedField loadMesh(const std::string& path, const std::string& format, const MeshOptions& options,
                     const std::string& nanPolicy)
{
    openvdb::initialize();
    Mesh m = readMesh(path, format, options);
    const std::string velocityName = chooseVelocity(m.leaves, options.vectorName, path);
    LoadedField out;
    out.format = format;
    out.notes = m.report.notes; // the read's (OpenFOAM: where the time came from): before the resampling's
    out.warnings = m.report.warnings;
    out.nonFiniteReplaced = checkVelocityValues(m.leaves, velocityName, nanPolicy, path);
    const Lattice l = chooseLattice(m, options, path);
    std::string maskName;
    const vtkSmartPointer<vtkImageData> image = probe(m, l, options, path, format, maskName);
    vtkDataArray* mask = image->GetPointData()->GetArray(maskName.c_str());
    if (!mask) detail::inputError(path, "VTK's resampling lost its mask");
    std::vector<char> inside;
    const std::vector<char> active = activeLattice(m, l, mask, inside);

    std::vector<Output> outs = outputsOf(m, image, velocityName, path);

    // The active lattice points, in lattice order; the values of each output there.
    std::vector<vtkIdType> lattice;
    for (std::size_t id = 0; id < active.size(); ++id)
        if (active[id]) lattice.push_back(vtkIdType(id));
    std::vector<vtkIdType> band; // active but not inside (point data are fitted there only)
    std::vector<std::size_t> allSlots(lattice.size()), bandSlots;
    for (std::size_t i = 0; i < lattice.size(); ++i) {
        allSlots[i] = i;
        if (!inside[std::size_t(lattice[i])]) {
            band.push_back(lattice[i]);
            bandSlots.push_back(i);
        }
    }
    bool cellData = false;
    std::map<std::string, std::vector<Output*>> bySources; // the leaves' kinds -> the outputs reading them
    for (auto& o : outs) {
        o.values.assign(lattice.size() * std::size_t(o.components), 0.0f);
        std::string kinds;
        for (std::size_t b = 0; b < m.leaves.size(); ++b) kinds += arrayKind(m.leaves[b], o.name);
        cellData = cellData || !o.fromPoints;
        bySources[kinds].push_back(&o);
        if (o.fromPoints)
            for (std::size_t i = 0; i < lattice.size(); ++i)
                if (inside[std::size_t(lattice[i])]) {
                    const vtkIdType id = lattice[i], nx = l.dims[0], ny = l.dims[1];
                    const vtkIdType probedId = (id % nx - 1) + l.probed[0] * ((id / nx) % ny - 1 + l.probed[1] * (id / (nx * ny) - 1));
                    for (int comp = 0; comp < o.components; ++comp)
                        o.values[i * std::size_t(o.components) + std::size_t(comp)] =
                            float(o.probed->GetComponent(probedId, comp));
                }
    }
    for (auto& [kinds, group] : bySources) {
        const Sources s = makeSources(m, kinds);
        if (s.points->GetNumberOfPoints() == 0) continue;
        std::vector<Output*> fromPoints, fromCells;
        for (Output* o : group) (o->fromPoints ? fromPoints : fromCells).push_back(o);
        if (!fromCells.empty()) fitValues(s, fromCells, lattice, allSlots, l);
        if (!fromPoints.empty()) fitValues(s, fromPoints, band, bandSlots, l);
    }

    // The grids.
    openvdb::Mat4d mat = openvdb::Mat4d::identity();
    mat.setToScale(openvdb::Vec3d(l.h));
    mat.setTranslation(openvdb::Vec3d(l.box[0][0], l.box[0][1], l.box[0][2])); // voxel (0,0,0): the low corner
    const auto xform = openvdb::math::Transform::createLinearTransform(mat);
    out.velocity = openvdb::Vec3SGrid::create(openvdb::Vec3s(0.0f));
    out.velocity->setTransform(xform->copy());
    std::uint64_t insideCount = 0;
    {
        auto vacc = out.velocity->getAccessor();
        const Output& v = outs.front();
        const vtkIdType nx = l.dims[0], ny = l.dims[1];
        auto coordOf = [&](vtkIdType id) { // the ring's low side at -1
            return openvdb::Coord(int(id % nx) - 1, int((id / nx) % ny) - 1, int(id / (nx * ny)) - 1);
        };
        for (std::size_t i = 0; i < lattice.size(); ++i) {
            const vtkIdType id = lattice[i];
            const openvdb::Coord ijk = coordOf(id);
            vacc.setValueOn(ijk, openvdb::Vec3s(v.values[3 * i], v.values[3 * i + 1], v.values[3 * i + 2]));
            insideCount += inside[std::size_t(id)] != 0;
        }
        for (std::size_t k = 1; k < outs.size(); ++k) {
            auto g = openvdb::FloatGrid::create(0.0f);
            g->setTransform(xform->copy());
            g->setName(outs[k].name);
            auto acc = g->getAccessor();
            for (std::size_t i = 0; i < lattice.size(); ++i) {
                const vtkIdType id = lattice[i];
                acc.setValueOn(coordOf(id), outs[k].values[i]);
            }
            g->pruneGrid();
            out.scalars.emplace(outs[k].name, g);
        }
    }
    if (insideCount == 0)
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
         << (m.time ? " at time " + num(*m.time) : "") << " onto " << l.probed[0] << "x" << l.probed[1] << "x" << l.probed[2]
         << " voxels of size " << num(l.h) << (options.voxelSize ? "" : " (" + l.rule + "; --voxel-size to change)")
         << ": " << insideCount << " inside the mesh, " << (lattice.size() - insideCount) << " in the band around it";
    out.notes.push_back(note.str());
    if (cellData)
        out.notes.push_back("cell data were fitted (weighted least squares, linear) over the " + std::to_string(kNeighbours)
                            + " nearest cell centres");
    if (out.nonFiniteReplaced)
        out.notes.push_back("replaced " + std::to_string(out.nonFiniteReplaced) + " NaN/Inf velocity components with 0");
    return out;
}

} // namespace vdbexport::mesh_module
