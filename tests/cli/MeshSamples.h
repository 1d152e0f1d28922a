// Meshes for the mesh-input tests, all holding one analytic flow: a solid rotation about the z axis
// (angular speed kOmega) plus an axial Poiseuille-like profile w = kW (1 - r²/R²), in the annulus
// kInner <= r <= kOuter, 0 <= z <= kHeight (an OpenFOAM box case holds the same flow in a box).
// Written with VTK's own data model and writers (.vtu, .vts, .pvd parts) and byte by byte where VTK
// has no writer (PLOT3D, OpenFOAM).
#pragma once

#include <vtkCellArray.h>
#include <vtkCell.h>
#include <vtkCellData.h>
#include <vtkIdList.h>
#include <vtkDataSetTriangleFilter.h>
#include <vtkFloatArray.h>
#include <vtkNew.h>
#include <vtkPointData.h>
#include <vtkPoints.h>
#include <vtkSmartPointer.h>
#include <vtkStructuredGrid.h>
#include <vtkUnstructuredGrid.h>
#include <vtkXMLStructuredGridWriter.h>
#include <vtkMultiBlockDataSet.h>
#include <vtkPartitionedDataSetCollection.h>
#include <vtkUnstructuredGridWriter.h>
#include <vtkXMLMultiBlockDataWriter.h>
#include <vtkXMLPartitionedDataSetCollectionWriter.h>
#include <vtkXMLUnstructuredGridWriter.h>

#include <openvdb/openvdb.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <array>
#include <map>
#include <string>
#include <vector>

namespace mesh_test {

namespace fs = std::filesystem;

constexpr double kOmega = 0.5, kW = 0.3, kInner = 0.3, kOuter = 1.0, kHeight = 2.0;

/// The flow at world position p (rotation `omega`).
inline openvdb::Vec3d flow(const openvdb::Vec3d& p, double omega = kOmega)
{
    const double r2 = p.x() * p.x() + p.y() * p.y();
    return {-omega * p.y(), omega * p.x(), kW * (1.0 - r2 / (kOuter * kOuter))};
}

inline vtkSmartPointer<vtkFloatArray> vectorArray(const char* name, vtkIdType n)
{
    auto a = vtkSmartPointer<vtkFloatArray>::New();
    a->SetName(name);
    a->SetNumberOfComponents(3);
    a->SetNumberOfTuples(n);
    return a;
}

/// Point data U (the flow, `omega`) and `speed` (its magnitude) on every point of `ds`.
inline void addFlow(vtkDataSet* ds, double omega = kOmega, const char* name = "U")
{
    const vtkIdType n = ds->GetNumberOfPoints();
    auto u = vectorArray(name, n);
    auto speed = vtkSmartPointer<vtkFloatArray>::New();
    speed->SetName("speed");
    speed->SetNumberOfTuples(n);
    double p[3];
    for (vtkIdType i = 0; i < n; ++i) {
        ds->GetPoint(i, p);
        const openvdb::Vec3d v = flow({p[0], p[1], p[2]}, omega);
        u->SetTuple3(i, v.x(), v.y(), v.z());
        speed->SetValue(i, float(v.length()));
    }
    ds->GetPointData()->AddArray(u);
    ds->GetPointData()->AddArray(speed);
}

/// Hexahedra of a Cartesian lattice of `n` cells per axis over [-1,1]²×[0,kHeight], kept where all
/// eight corners lie in the annulus: a stair-stepped annulus with a hole down its middle.
inline vtkSmartPointer<vtkUnstructuredGrid> hexLattice(int n, double omega, double inner, double outer);

inline vtkSmartPointer<vtkUnstructuredGrid> hexAnnulus(int n, double omega = kOmega)
{
    return hexLattice(n, omega, kInner, kOuter);
}

/// Every hexahedron of the lattice (a box, no hole).
inline vtkSmartPointer<vtkUnstructuredGrid> hexBox(int n) { return hexLattice(n, kOmega, 0.0, 2.0); }

inline vtkSmartPointer<vtkUnstructuredGrid> hexLattice(int n, double omega, double inner, double outer)
{
    auto grid = vtkSmartPointer<vtkUnstructuredGrid>::New();
    vtkNew<vtkPoints> pts;
    const double h = 2.0 / n, hz = kHeight / n;
    auto id = [n](int i, int j, int k) { return vtkIdType(i + (n + 1) * (j + (n + 1) * k)); };
    for (int k = 0; k <= n; ++k)
        for (int j = 0; j <= n; ++j)
            for (int i = 0; i <= n; ++i) pts->InsertNextPoint(-1 + i * h, -1 + j * h, k * hz);
    grid->SetPoints(pts);
    auto inside = [&](int i, int j) {
        const double x = -1 + i * h, y = -1 + j * h, r = std::sqrt(x * x + y * y);
        return r >= inner && r <= outer;
    };
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                if (!(inside(i, j) && inside(i + 1, j) && inside(i, j + 1) && inside(i + 1, j + 1))) continue;
                const vtkIdType c[8] = {id(i, j, k),     id(i + 1, j, k),     id(i + 1, j + 1, k),     id(i, j + 1, k),
                                        id(i, j, k + 1), id(i + 1, j, k + 1), id(i + 1, j + 1, k + 1), id(i, j + 1, k + 1)};
                grid->InsertNextCell(VTK_HEXAHEDRON, 8, c);
            }
    addFlow(grid, omega);
    return grid;
}

/// The same annulus cut into tetrahedra (VTK's vtkDataSetTriangleFilter).
inline vtkSmartPointer<vtkUnstructuredGrid> tetAnnulus(int n)
{
    vtkNew<vtkDataSetTriangleFilter> tets;
    tets->SetInputData(hexAnnulus(n));
    tets->Update();
    vtkSmartPointer<vtkUnstructuredGrid> out = tets->GetOutput();
    return out;
}

/// A curvilinear O-grid of the annulus: nr × nt × nz points in (r, θ, z), θ closing on itself.
struct OGrid
{
    int nr, nt, nz;
    openvdb::Vec3d point(int i, int j, int k) const
    {
        const double r = kInner + (kOuter - kInner) * i / (nr - 1), t = 2 * M_PI * j / (nt - 1);
        return {r * std::cos(t), r * std::sin(t), kHeight * k / (nz - 1)};
    }
};

inline vtkSmartPointer<vtkStructuredGrid> structuredAnnulus(const OGrid& g)
{
    auto grid = vtkSmartPointer<vtkStructuredGrid>::New();
    grid->SetDimensions(g.nr, g.nt, g.nz);
    vtkNew<vtkPoints> pts;
    for (int k = 0; k < g.nz; ++k)
        for (int j = 0; j < g.nt; ++j)
            for (int i = 0; i < g.nr; ++i) {
                const auto p = g.point(i, j, k);
                pts->InsertNextPoint(p.x(), p.y(), p.z());
            }
    grid->SetPoints(pts);
    addFlow(grid);
    return grid;
}

/// `grid` cut in two at z = kHeight/2 by cell centre: two grids sharing all the points (each with
/// every point and its data; cells split between them).
inline std::array<vtkSmartPointer<vtkUnstructuredGrid>, 2> splitByZ(vtkUnstructuredGrid* grid)
{
    std::array<vtkSmartPointer<vtkUnstructuredGrid>, 2> halves;
    for (int h = 0; h < 2; ++h) {
        halves[h] = vtkSmartPointer<vtkUnstructuredGrid>::New();
        halves[h]->SetPoints(grid->GetPoints());
        halves[h]->GetPointData()->ShallowCopy(grid->GetPointData());
    }
    double b[6];
    for (vtkIdType c = 0; c < grid->GetNumberOfCells(); ++c) {
        grid->GetCellBounds(c, b);
        vtkIdList* ids = grid->GetCell(c)->GetPointIds();
        halves[0.5 * (b[4] + b[5]) < 0.5 * kHeight ? 0 : 1]->InsertNextCell(grid->GetCellType(c), ids);
    }
    return halves;
}

/// The halves of `grid` as a two-block .vtm (and its folder of .vtu pieces).
inline void writeVtm(vtkUnstructuredGrid* grid, const fs::path& path)
{
    const auto halves = splitByZ(grid);
    vtkNew<vtkMultiBlockDataSet> blocks;
    blocks->SetBlock(0, halves[0]);
    blocks->SetBlock(1, halves[1]);
    vtkNew<vtkXMLMultiBlockDataWriter> w;
    w->SetInputData(blocks);
    w->SetFileName(path.c_str());
    w->Write();
}

/// The halves of `grid` as one partitioned data set of two partitions in a .vtpc.
inline void writeVtpc(vtkUnstructuredGrid* grid, const fs::path& path)
{
    const auto halves = splitByZ(grid);
    vtkNew<vtkPartitionedDataSetCollection> coll;
    coll->SetPartition(0, 0, halves[0]);
    coll->SetPartition(0, 1, halves[1]);
    vtkNew<vtkXMLPartitionedDataSetCollectionWriter> w;
    w->SetInputData(coll);
    w->SetFileName(path.c_str());
    w->Write();
}

/// A legacy (binary) .vtk UNSTRUCTURED_GRID.
inline void writeLegacyVtk(vtkUnstructuredGrid* grid, const fs::path& path)
{
    vtkNew<vtkUnstructuredGridWriter> w;
    w->SetInputData(grid);
    w->SetFileName(path.c_str());
    w->SetFileTypeToBinary();
    w->Write();
}

inline void writeVtu(vtkUnstructuredGrid* grid, const fs::path& path, bool ascii = false)
{
    vtkNew<vtkXMLUnstructuredGridWriter> w;
    w->SetInputData(grid);
    w->SetFileName(path.c_str());
    if (ascii) w->SetDataModeToAscii();
    w->Write();
}

inline void writeVts(vtkStructuredGrid* grid, const fs::path& path)
{
    vtkNew<vtkXMLStructuredGridWriter> w;
    w->SetInputData(grid);
    w->SetFileName(path.c_str());
    w->Write();
}

template<typename T>
void put(std::string& s, T v)
{
    char b[sizeof(T)];
    std::memcpy(b, &v, sizeof(T));
    s.append(b, sizeof(T));
}

/// A Fortran unformatted record: length, bytes, length.
inline void record(std::string& out, const std::string& bytes)
{
    put<std::int32_t>(out, std::int32_t(bytes.size()));
    out += bytes;
    put<std::int32_t>(out, std::int32_t(bytes.size()));
}

/// PLOT3D whole, single-grid, 3D, little-endian float32 files with Fortran record markers (as most
/// CFD codes write them): the O-grid in `xyz`, density 1.2 and momentum 1.2·flow in `q`.
inline void writePlot3d(const OGrid& g, const fs::path& xyz, const fs::path& q)
{
    std::string dims;
    for (int d : {g.nr, g.nt, g.nz}) put<std::int32_t>(dims, d);
    std::string coords, sol;
    for (int c = 0; c < 3; ++c)
        for (int k = 0; k < g.nz; ++k)
            for (int j = 0; j < g.nt; ++j)
                for (int i = 0; i < g.nr; ++i) put<float>(coords, float(g.point(i, j, k)[c]));
    std::string grid;
    record(grid, dims);
    record(grid, coords);
    std::ofstream(xyz, std::ios::binary) << grid;
    std::string head;
    for (float v : {0.2f, 0.0f, 1000.0f, 0.0f}) put<float>(head, v); // Mach, alpha, Reynolds, time
    const double rho = 1.2;
    for (int c = 0; c < 5; ++c)
        for (int k = 0; k < g.nz; ++k)
            for (int j = 0; j < g.nt; ++j)
                for (int i = 0; i < g.nr; ++i) {
                    const auto u = flow(g.point(i, j, k));
                    const double v = c == 0 ? rho : c < 4 ? rho * u[c - 1] : 2.5 + 0.5 * rho * u.lengthSqr();
                    put<float>(sol, float(v));
                }
    std::string qf;
    record(qf, dims);
    record(qf, head);
    record(qf, sol);
    std::ofstream(q, std::ios::binary) << qf;
}

/// An OpenFOAM case of n³ hexahedra over [-1,1]²×[0,kHeight]: constant/polyMesh (ASCII), U at the
/// cell centres in each time directory of `times` (rotation `omegas[t]`), every boundary face one
/// fixedValue patch `walls` holding the flow at the face centres.
inline void writeOpenFoamCase(const fs::path& dir, int n, const std::vector<std::string>& times,
                              const std::vector<double>& omegas, bool withU = true)
{
    fs::create_directories(dir / "system");
    fs::create_directories(dir / "constant" / "polyMesh");
    auto header = [](const std::string& cls, const std::string& object, const std::string& location = "") {
        return "FoamFile\n{\n    version 2.0;\n    format ascii;\n    class " + cls + ";\n"
               + (location.empty() ? "" : "    location \"" + location + "\";\n") + "    object " + object + ";\n}\n\n";
    };
    std::ofstream(dir / "system" / "controlDict")
        << header("dictionary", "controlDict", "system")
        << "application icoFoam;\nstartFrom startTime;\nstartTime 0;\nstopAt endTime;\nendTime 1;\ndeltaT 0.5;\n"
           "writeControl timeStep;\nwriteInterval 1;\n";
    const double h = 2.0 / n, hz = kHeight / n;
    auto pid = [n](int i, int j, int k) { return i + (n + 1) * (j + (n + 1) * k); };
    auto cid = [n](int i, int j, int k) { return i + n * (j + n * k); };
    auto pos = [&](double i, double j, double k) { return openvdb::Vec3d(-1 + i * h, -1 + j * h, k * hz); };
    {
        std::ofstream p(dir / "constant" / "polyMesh" / "points");
        p << header("vectorField", "points", "constant/polyMesh") << (n + 1) * (n + 1) * (n + 1) << "\n(\n";
        for (int k = 0; k <= n; ++k)
            for (int j = 0; j <= n; ++j)
                for (int i = 0; i <= n; ++i) {
                    const auto x = pos(i, j, k);
                    p << "(" << x.x() << " " << x.y() << " " << x.z() << ")\n";
                }
        p << ")\n";
    }
    struct Face
    {
        std::array<int, 4> v;
        int owner, neighbour;
        openvdb::Vec3d centre;
    };
    std::vector<Face> internal, boundary;
    // The +x, +y, +z faces of cell (i,j,k), vertices ordered so the normal points along +axis.
    auto faceOf = [&](int axis, int i, int j, int k) -> std::array<int, 4> {
        if (axis == 0) return {pid(i + 1, j, k), pid(i + 1, j + 1, k), pid(i + 1, j + 1, k + 1), pid(i + 1, j, k + 1)};
        if (axis == 1) return {pid(i, j + 1, k), pid(i, j + 1, k + 1), pid(i + 1, j + 1, k + 1), pid(i + 1, j + 1, k)};
        return {pid(i, j, k + 1), pid(i + 1, j, k + 1), pid(i + 1, j + 1, k + 1), pid(i, j + 1, k + 1)};
    };
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j)
            for (int i = 0; i < n; ++i) {
                const int c = cid(i, j, k);
                const int idx[3] = {i, j, k};
                for (int axis = 0; axis < 3; ++axis) {
                    openvdb::Vec3d centre = pos(i + 0.5, j + 0.5, k + 0.5);
                    centre[axis] += 0.5 * (axis == 2 ? hz : h);
                    if (idx[axis] + 1 < n) {
                        const int nb = axis == 0 ? cid(i + 1, j, k) : axis == 1 ? cid(i, j + 1, k) : cid(i, j, k + 1);
                        internal.push_back({faceOf(axis, i, j, k), c, nb, centre});
                    } else {
                        boundary.push_back({faceOf(axis, i, j, k), c, -1, centre});
                    }
                    if (idx[axis] == 0) { // the -axis boundary face: the +axis face of the cell before, reversed
                        const int ii = axis == 0 ? i - 1 : i, jj = axis == 1 ? j - 1 : j, kk = axis == 2 ? k - 1 : k;
                        auto v = faceOf(axis, ii, jj, kk);
                        std::swap(v[1], v[3]);
                        openvdb::Vec3d lc = pos(i + 0.5, j + 0.5, k + 0.5);
                        lc[axis] -= 0.5 * (axis == 2 ? hz : h);
                        boundary.push_back({v, c, -1, lc});
                    }
                }
            }
    auto writeList = [&](const std::string& name, const std::string& cls, const std::vector<std::string>& items) {
        std::ofstream f(dir / "constant" / "polyMesh" / name);
        f << header(cls, name, "constant/polyMesh") << items.size() << "\n(\n";
        for (const auto& s : items) f << s << "\n";
        f << ")\n";
    };
    std::vector<std::string> faces, owner, neighbour;
    for (const auto* list : {&internal, &boundary})
        for (const auto& f : *list) {
            faces.push_back("4(" + std::to_string(f.v[0]) + " " + std::to_string(f.v[1]) + " " + std::to_string(f.v[2]) + " "
                            + std::to_string(f.v[3]) + ")");
            owner.push_back(std::to_string(f.owner));
            if (f.neighbour >= 0) neighbour.push_back(std::to_string(f.neighbour));
        }
    writeList("faces", "faceList", faces);
    writeList("owner", "labelList", owner);
    writeList("neighbour", "labelList", neighbour);
    std::ofstream(dir / "constant" / "polyMesh" / "boundary")
        << header("polyBoundaryMesh", "boundary", "constant/polyMesh") << "1\n(\n    walls\n    {\n        type wall;\n"
        << "        nFaces " << boundary.size() << ";\n        startFace " << internal.size() << ";\n    }\n)\n";
    for (std::size_t t = 0; t < times.size(); ++t) {
        fs::create_directories(dir / times[t]);
        if (!withU) {
            std::ofstream(dir / times[t] / "p") << header("volScalarField", "p", times[t])
                                               << "dimensions [0 2 -2 0 0 0 0];\ninternalField uniform 0;\n"
                                                  "boundaryField\n{\n    walls\n    {\n        type zeroGradient;\n    }\n}\n";
            continue;
        }
        std::ofstream u(dir / times[t] / "U");
        u << header("volVectorField", "U", times[t]) << "dimensions [0 1 -1 0 0 0 0];\n\ninternalField nonuniform List<vector>\n"
          << n * n * n << "\n(\n";
        for (int k = 0; k < n; ++k)
            for (int j = 0; j < n; ++j)
                for (int i = 0; i < n; ++i) {
                    const auto v = flow(pos(i + 0.5, j + 0.5, k + 0.5), omegas[t]);
                    u << "(" << v.x() << " " << v.y() << " " << v.z() << ")\n";
                }
        u << ")\n;\n\nboundaryField\n{\n    walls\n    {\n        type fixedValue;\n        value nonuniform List<vector>\n"
          << boundary.size() << "\n(\n";
        for (const auto& f : boundary) {
            const auto v = flow(f.centre, omegas[t]);
            u << "(" << v.x() << " " << v.y() << " " << v.z() << ")\n";
        }
        u << ")\n;\n    }\n}\n";
    }
}

} // namespace mesh_test
