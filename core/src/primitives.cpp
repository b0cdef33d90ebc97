#include "riemesh/primitives.h"

#include <array>
#include <cmath>
#include <map>
#include <stdexcept>
#include <utility>
#include <vector>

namespace riemesh {

namespace {

/// Adds a triangle with the given winding, flipping it when its normal points toward `inside`.
void addOriented(Mesh& mesh, VertexHandle a, VertexHandle b, VertexHandle c, const Vec3& inside)
{
    const Vec3 pa = position(mesh, a), pb = position(mesh, b), pc = position(mesh, c);
    const Vec3 n = (pb - pa).cross(pc - pa);
    if (n.dot((pa + pb + pc) / 3.0 - inside) >= 0) mesh.add_face(a, b, c);
    else mesh.add_face(a, c, b);
}

} // namespace

Mesh makeBox(const Vec3& lo, const Vec3& hi, double edgeLength)
{
    if (!(edgeLength > 0)) throw std::invalid_argument("makeBox: edge length must be > 0");
    if (!(hi.array() > lo.array()).all()) throw std::invalid_argument("makeBox: empty box");
    Mesh mesh;
    const Vec3 size = hi - lo;
    int n[3];
    for (int a = 0; a < 3; ++a) n[a] = std::max(1, int(std::ceil(size[a] / edgeLength - 1e-9)));
    // Vertices on the surface lattice, shared between faces through a map on lattice indices.
    std::map<std::array<int, 3>, VertexHandle> lattice;
    auto vertex = [&](int i, int j, int k) {
        std::array<int, 3> key{i, j, k};
        auto it = lattice.find(key);
        if (it != lattice.end()) return it->second;
        Vec3 p(lo.x() + size.x() * i / n[0], lo.y() + size.y() * j / n[1], lo.z() + size.z() * k / n[2]);
        VertexHandle v = mesh.add_vertex(toPoint(p));
        lattice.emplace(key, v);
        return v;
    };
    const Vec3 center = 0.5 * (lo + hi);
    // For each axis `a` and side s in {0, n[a]}, grid over the other two axes (b, c).
    for (int a = 0; a < 3; ++a) {
        const int b = (a + 1) % 3, c = (a + 2) % 3;
        for (int side = 0; side < 2; ++side) {
            const int fixed = side ? n[a] : 0;
            for (int u = 0; u < n[b]; ++u) {
                for (int w = 0; w < n[c]; ++w) {
                    auto at = [&](int du, int dw) {
                        int idx[3];
                        idx[a] = fixed;
                        idx[b] = u + du;
                        idx[c] = w + dw;
                        return vertex(idx[0], idx[1], idx[2]);
                    };
                    VertexHandle v00 = at(0, 0), v10 = at(1, 0), v01 = at(0, 1), v11 = at(1, 1);
                    // Alternate the diagonal for a more isotropic triangulation.
                    if ((u + w) % 2 == 0) {
                        addOriented(mesh, v00, v10, v11, center);
                        addOriented(mesh, v00, v11, v01, center);
                    } else {
                        addOriented(mesh, v00, v10, v01, center);
                        addOriented(mesh, v10, v11, v01, center);
                    }
                }
            }
        }
    }
    prepareMesh(mesh); // after add_vertex: new vertices' velocities would be uninitialised
    return mesh;
}

Mesh makeIcosphere(const Vec3& center, double radius, int subdivisions)
{
    if (!(radius > 0)) throw std::invalid_argument("makeIcosphere: radius must be > 0");
    if (subdivisions < 0 || subdivisions > 8) throw std::invalid_argument("makeIcosphere: subdivisions in [0, 8]");
    const double t = (1.0 + std::sqrt(5.0)) / 2.0;
    std::vector<Vec3> pts = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                             {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
    for (auto& p : pts) p.normalize();
    std::vector<std::array<int, 3>> tris = {{0, 11, 5}, {0, 5, 1}, {0, 1, 7}, {0, 7, 10}, {0, 10, 11},
                                            {1, 5, 9}, {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                            {3, 9, 4}, {3, 4, 2}, {3, 2, 6}, {3, 6, 8}, {3, 8, 9},
                                            {4, 9, 5}, {2, 4, 11}, {6, 2, 10}, {8, 6, 7}, {9, 8, 1}};
    for (int s = 0; s < subdivisions; ++s) {
        std::map<std::pair<int, int>, int> mid;
        auto midpoint = [&](int a, int b) {
            auto key = std::minmax(a, b);
            auto it = mid.find(key);
            if (it != mid.end()) return it->second;
            pts.push_back((pts[a] + pts[b]).normalized());
            int id = int(pts.size()) - 1;
            mid.emplace(key, id);
            return id;
        };
        std::vector<std::array<int, 3>> next;
        next.reserve(tris.size() * 4);
        for (auto& f : tris) {
            int ab = midpoint(f[0], f[1]), bc = midpoint(f[1], f[2]), ca = midpoint(f[2], f[0]);
            next.push_back({f[0], ab, ca});
            next.push_back({f[1], bc, ab});
            next.push_back({f[2], ca, bc});
            next.push_back({ab, bc, ca});
        }
        tris.swap(next);
    }
    Mesh mesh;
    std::vector<VertexHandle> vh;
    vh.reserve(pts.size());
    for (auto& p : pts) vh.push_back(mesh.add_vertex(toPoint(center + radius * p)));
    for (auto& f : tris) addOriented(mesh, vh[f[0]], vh[f[1]], vh[f[2]], center);
    prepareMesh(mesh); // after add_vertex: new vertices' velocities would be uninitialised
    return mesh;
}

Mesh makeTorus(const Vec3& center, double majorRadius, double minorRadius, int majorSegments,
               int minorSegments)
{
    if (!(majorRadius > minorRadius && minorRadius > 0))
        throw std::invalid_argument("makeTorus: need majorRadius > minorRadius > 0");
    if (majorSegments < 3 || minorSegments < 3) throw std::invalid_argument("makeTorus: need >= 3 segments");
    Mesh mesh;
    std::vector<VertexHandle> vh(std::size_t(majorSegments) * minorSegments);
    for (int i = 0; i < majorSegments; ++i) {
        const double u = 2 * M_PI * i / majorSegments;
        for (int j = 0; j < minorSegments; ++j) {
            const double w = 2 * M_PI * j / minorSegments;
            const double r = majorRadius + minorRadius * std::cos(w);
            Vec3 p(r * std::cos(u), r * std::sin(u), minorRadius * std::sin(w));
            vh[i * minorSegments + j] = mesh.add_vertex(toPoint(center + p));
        }
    }
    for (int i = 0; i < majorSegments; ++i) {
        const double u = 2 * M_PI * (i + 0.5) / majorSegments;
        const Vec3 tube = center + majorRadius * Vec3(std::cos(u), std::sin(u), 0);
        for (int j = 0; j < minorSegments; ++j) {
            const int i1 = (i + 1) % majorSegments, j1 = (j + 1) % minorSegments;
            VertexHandle a = vh[i * minorSegments + j], b = vh[i1 * minorSegments + j];
            VertexHandle c = vh[i1 * minorSegments + j1], d = vh[i * minorSegments + j1];
            addOriented(mesh, a, b, c, tube);
            addOriented(mesh, a, c, d, tube);
        }
    }
    prepareMesh(mesh); // after add_vertex: new vertices' velocities would be uninitialised
    return mesh;
}

} // namespace riemesh
