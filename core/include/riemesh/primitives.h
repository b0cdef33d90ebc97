// riemesh/primitives.h: closed, outward-oriented meshes built in code (fixtures and initialisation).
#pragma once

#include "riemesh/mesh.h"

namespace riemesh {

/// Axis-aligned box [lo, hi] (world units), each face triangulated on a regular grid whose
/// cells are at most `edgeLength` (world units) on a side. Genus 0.
Mesh makeBox(const Vec3& lo, const Vec3& hi, double edgeLength);

/// Icosphere of `radius` (world units) around `center`, `subdivisions` times subdivided
/// (20 * 4^subdivisions faces). Genus 0.
Mesh makeIcosphere(const Vec3& center, double radius, int subdivisions);

/// Torus around the z axis through `center`: tube centre radius `majorRadius`, tube radius
/// `minorRadius` (world units), `majorSegments` x `minorSegments` quads split in two. Genus 1.
Mesh makeTorus(const Vec3& center, double majorRadius, double minorRadius, int majorSegments,
               int minorSegments);

} // namespace riemesh
