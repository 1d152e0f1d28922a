#include "lic/field/Region.h"

#include <openvdb/math/Mat3.h>
#include <openvdb/tools/GridOperators.h>

#include <tbb/parallel_for.h>

namespace lic {

std::vector<openvdb::Vec3d> ridgePoints(const openvdb::FloatGrid& scalar, double threshold)
{
    using openvdb::Coord;
    using openvdb::Vec3d;
    using LeafT = openvdb::FloatTree::LeafNodeType;
    std::vector<const LeafT*> leaves;
    scalar.tree().getNodes(leaves);
    std::vector<std::vector<Vec3d>> perLeaf(leaves.size());
    tbb::parallel_for(tbb::blocked_range<std::size_t>(0, leaves.size()), [&](const auto& r) {
        auto acc = scalar.getConstAccessor();
        for (std::size_t l = r.begin(); l != r.end(); ++l) {
            for (auto it = leaves[l]->cbeginValueOn(); it; ++it) {
                const float s0 = *it;
                if (!(s0 > threshold)) continue;
                const Coord c = it.getCoord();
                float s[3][3][3];
                bool complete = true;
                for (int x = -1; x <= 1 && complete; ++x)
                    for (int y = -1; y <= 1 && complete; ++y)
                        for (int z = -1; z <= 1 && complete; ++z)
                            complete = acc.probeValue(c.offsetBy(x, y, z), s[x + 1][y + 1][z + 1]);
                if (!complete) continue;
                const Vec3d g(0.5 * (s[2][1][1] - s[0][1][1]), 0.5 * (s[1][2][1] - s[1][0][1]),
                              0.5 * (s[1][1][2] - s[1][1][0]));
                openvdb::math::Mat3d H;
                H(0, 0) = s[2][1][1] - 2.0 * s0 + s[0][1][1];
                H(1, 1) = s[1][2][1] - 2.0 * s0 + s[1][0][1];
                H(2, 2) = s[1][1][2] - 2.0 * s0 + s[1][1][0];
                H(0, 1) = H(1, 0) = 0.25 * (s[2][2][1] - s[2][0][1] - s[0][2][1] + s[0][0][1]);
                H(0, 2) = H(2, 0) = 0.25 * (s[2][1][2] - s[2][1][0] - s[0][1][2] + s[0][1][0]);
                H(1, 2) = H(2, 1) = 0.25 * (s[1][2][2] - s[1][2][0] - s[1][0][2] + s[1][0][0]);
                openvdb::math::Mat3d Q;
                Vec3d D;
                if (!openvdb::math::diagonalizeSymmetricMatrix(H, Q, D)) continue;
                int m = 0;
                for (int a = 1; a < 3; ++a)
                    if (D[a] < D[m]) m = a;
                if (!(D[m] < 0.0)) continue;
                const Vec3d e(Q(0, m), Q(1, m), Q(2, m));
                const double t = -g.dot(e) / D[m];
                if (std::abs(t) > 0.5) continue;
                perLeaf[l].push_back(scalar.indexToWorld(c.asVec3d() + t * e));
            }
        }
    });
    std::vector<Vec3d> out;
    for (const auto& v : perLeaf) out.insert(out.end(), v.begin(), v.end());
    return out;
}

openvdb::FloatGrid::Ptr gradientMagnitude(const openvdb::FloatGrid& scalar, const std::string& name)
{
    auto grad = openvdb::tools::gradient(scalar);
    auto mag = openvdb::tools::magnitude(*grad);
    mag->setName(name);
    return mag;
}

} // namespace lic
