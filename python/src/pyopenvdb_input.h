// python/src/pyopenvdb_input.h: pyopenvdb grids (Debian python3-openvdb, a Boost.Python module over the
// same libopenvdb) as riemesh Volumes. Kept apart from the pybind11 module: it is the one file that
// includes OpenVDB and Boost.Python.
#pragma once

#include "riemesh/vdb/volume.h"

#include <Python.h>

#include <optional>

namespace riemesh::python {

/// A Volume holding a deep copy of `object` when it is a pyopenvdb FloatGrid or DoubleGrid (its
/// transform, name and class kept); nullopt when it is not a pyopenvdb object. Throws
/// std::invalid_argument for a pyopenvdb grid of another type, or one Volume refuses (empty,
/// non-finite, frustum transform, flat). Call with the GIL held.
std::optional<vdb::Volume> volumeFromPyOpenVDB(PyObject* object);

/// True when the module was built with Boost.Python (pyopenvdb grids are read directly).
bool hasPyOpenVDB();

} // namespace riemesh::python
