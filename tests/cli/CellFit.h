// How a field resampled from a mesh reads back at the mesh's own cells (issue 54 items 4, 5): the
// share of random points inside the cells whose 8 trilinear corners are active, and at the cell
// centres the trilinear value against each cell's value (mean relative error, mean speed ratio).
// Shared by test_mesh (synthetic meshes) and test_openfoam (real OpenFOAM cases).
#pragma once

#include "vdbexport/io/FieldInput.h"

#include <vtkCellData.h>
#include <vtkDataArray.h>
#include <vtkDataSet.h>
#include <vtkIdList.h>
#include <vtkNew.h>

#include <openvdb/openvdb.h>

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <random>
#include <string>

namespace mesh_test {

/// How a resampled field reads back at the cells of the mesh it came from.
struct CellFit
{
    double pointsCovered = 0; ///< random points inside cells whose 8 trilinear corners are active
    double pointsNearest = 0; ///< ... whose nearest voxel is active
    double centresCovered = 0; ///< cell centres whose 8 trilinear corners are active
    double relError = 0;      ///< Σ|trilinear(centre) - cell value| / Σ|cell value| over the covered centres
    double speedRatio = 0;    ///< mean |trilinear(centre)| / mean |cell value| over the covered centres
    std::uint64_t cells = 0;
};

/// The trilinear value of `g` at world position p, and whether its 8 corners are active.
inline bool trilinear(const openvdb::Vec3SGrid& g, const openvdb::Vec3d& p, openvdb::Vec3d& value)
{
    const openvdb::Vec3d x = g.transform().worldToIndex(p);
    const openvdb::Coord c0(int(std::floor(x.x())), int(std::floor(x.y())), int(std::floor(x.z())));
    const openvdb::Vec3d f = x - openvdb::Vec3d(c0.x(), c0.y(), c0.z());
    auto acc = g.getConstAccessor();
    bool all = true;
    value = openvdb::Vec3d(0.0);
    for (int k = 0; k < 2; ++k)
        for (int j = 0; j < 2; ++j)
            for (int i = 0; i < 2; ++i) {
                const openvdb::Coord c = c0.offsetBy(i, j, k);
                all = all && acc.isValueOn(c);
                const double w = (i ? f.x() : 1 - f.x()) * (j ? f.y() : 1 - f.y()) * (k ? f.z() : 1 - f.z());
                value += w * openvdb::Vec3d(acc.getValue(c));
            }
    return all;
}

/// Compare `g` with the cell values `array` of `mesh` at the cells' centres (mean of their points),
/// and count how much of the cells' volume (random points between a centre and a corner) is covered.
inline CellFit fitToCells(const openvdb::Vec3SGrid& g, vtkDataSet* mesh, const char* array)
{
    CellFit fit;
    vtkDataArray* u = mesh->GetCellData()->GetArray(array);
    EXPECT_TRUE(u) << array;
    if (!u) return fit;
    std::mt19937 rng(54);
    std::uniform_real_distribution<double> unit(0.0, 0.95);
    double err = 0, norm = 0, speed = 0, cellSpeed = 0;
    std::uint64_t covered = 0, points = 0, pointsCovered = 0, pointsNearest = 0;
    auto acc = g.getConstAccessor();
    vtkNew<vtkIdList> ids;
    for (vtkIdType c = 0; c < mesh->GetNumberOfCells(); ++c) {
        mesh->GetCellPoints(c, ids);
        openvdb::Vec3d centre(0.0);
        double p[3];
        for (vtkIdType i = 0; i < ids->GetNumberOfIds(); ++i) {
            mesh->GetPoint(ids->GetId(i), p);
            centre += openvdb::Vec3d(p[0], p[1], p[2]);
        }
        centre /= double(ids->GetNumberOfIds());
        ++fit.cells;
        for (int r = 0; r < 2; ++r) { // two random points per cell, between the centre and a corner
            mesh->GetPoint(ids->GetId(vtkIdType(rng() % std::uint32_t(ids->GetNumberOfIds()))), p);
            const openvdb::Vec3d q = centre + unit(rng) * (openvdb::Vec3d(p[0], p[1], p[2]) - centre);
            openvdb::Vec3d v;
            ++points;
            pointsCovered += trilinear(g, q, v);
            pointsNearest += acc.isValueOn(openvdb::Coord::round(g.transform().worldToIndex(q)));
        }
        openvdb::Vec3d v;
        if (!trilinear(g, centre, v)) continue;
        ++covered;
        const openvdb::Vec3d cell(u->GetComponent(c, 0), u->GetComponent(c, 1), u->GetComponent(c, 2));
        err += (v - cell).length();
        norm += cell.length();
        speed += v.length();
        cellSpeed += cell.length();
    }
    fit.pointsCovered = double(pointsCovered) / double(std::max<std::uint64_t>(1, points));
    fit.pointsNearest = double(pointsNearest) / double(std::max<std::uint64_t>(1, points));
    fit.centresCovered = double(covered) / double(std::max<std::uint64_t>(1, fit.cells));
    fit.relError = norm > 0 ? err / norm : 1;
    fit.speedRatio = cellSpeed > 0 ? speed / cellSpeed : 0;
    return fit;
}

inline void printFit(const std::string& what, const vdbexport::LoadedField& f, const CellFit& fit)
{
    std::cout << "  " << what << ": voxel " << f.velocity->voxelSize()[0] << ", " << f.velocity->activeVoxelCount()
              << " active; random points: " << 100 * fit.pointsCovered << " % with 8 corners active ("
              << 100 * fit.pointsNearest << " % nearest voxel active); centres covered " << 100 * fit.centresCovered
              << " %, mean relative error " << 100 * fit.relError << " %, mean speed " << 100 * fit.speedRatio
              << " % of the cells'\n";
    for (const auto& n : f.notes) std::cout << "    " << n << "\n";
}

} // namespace mesh_test
