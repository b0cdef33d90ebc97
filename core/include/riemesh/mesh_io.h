// riemesh/mesh_io.h: mesh files. OBJ, PLY (binary little-endian and ascii), OFF, STL (binary and
// ascii), chosen by extension. Written with outward normals (positive signed volume); written to a
// temporary file beside the target, then renamed, so a failed write never leaves a partial file.
#pragma once

#include "riemesh/mesh.h"

#include <string>
#include <string_view>

namespace riemesh {

enum class MeshFormat { Obj, Ply, PlyAscii, Off, Stl };

/// Format from the file extension (.obj .ply .off .stl, case-insensitive). Throws
/// std::invalid_argument naming the extension when unknown.
MeshFormat meshFormatFromPath(const std::string& path);

/// Reads a closed triangle mesh (polygons are fanned, duplicate STL vertices merged). Throws
/// std::runtime_error naming the file and the problem (missing, empty, truncated, malformed,
/// non-finite coordinates, out-of-range indices, not a closed manifold).
Mesh readMesh(const std::string& path);

/// The same from a file's bytes in memory (the browser's dropped files, the fuzzer); `name` stands
/// for the file in messages.
Mesh readMeshFromBytes(std::string_view bytes, MeshFormat format, const std::string& name);

/// Writes `mesh` in `format` (default: from the extension) atomically. `comment` goes in the file's
/// header where the format has one. Throws std::runtime_error on failure (nothing is left behind).
void writeMesh(const std::string& path, const Mesh& mesh, const std::string& comment = {});
void writeMesh(const std::string& path, const Mesh& mesh, MeshFormat format, const std::string& comment = {});

} // namespace riemesh
