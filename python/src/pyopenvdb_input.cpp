// pyopenvdb grids as Volumes (pyopenvdb_input.h). pyopenvdb wraps openvdb::FloatGrid with Boost.Python
// (class_<Grid, Grid::Ptr>); linking the same libboost_python shares its converter registry, so
// boost::python::extract reaches the C++ grid behind the Python object.
#include "pyopenvdb_input.h"

#if RIEMESH_WITH_BOOST_PYTHON
#include <boost/python.hpp>
#endif

#include "riemesh/vdb/volume_grids.h"

#include <openvdb/openvdb.h>

#include <stdexcept>
#include <string>

namespace riemesh::python {

namespace {

/// The name of the module that defines `object`'s type ("" when unknown).
std::string typeModule(PyObject* object)
{
    PyObject* module = PyObject_GetAttrString(reinterpret_cast<PyObject*>(Py_TYPE(object)), "__module__");
    if (!module) {
        PyErr_Clear();
        return {};
    }
    std::string name;
    if (PyUnicode_Check(module)) name = PyUnicode_AsUTF8(module);
    Py_DECREF(module);
    return name;
}

vdb::Volume volumeOf(openvdb::FloatGrid::Ptr grid)
{
    if (grid->getName().empty()) grid->setName("pyopenvdb");
    return vdb::VolumeGrids::fromImage(grid, "pyopenvdb", "grid transform");
}

} // namespace

bool hasPyOpenVDB() { return RIEMESH_WITH_BOOST_PYTHON; }

std::optional<vdb::Volume> volumeFromPyOpenVDB(PyObject* object)
{
    if (typeModule(object) != "pyopenvdb") return std::nullopt;
    const std::string type = Py_TYPE(object)->tp_name;
#if RIEMESH_WITH_BOOST_PYTHON
    namespace bp = boost::python;
    bp::object o{bp::handle<>(bp::borrowed(object))};
    if (bp::extract<openvdb::FloatGrid&> asFloat(o); asFloat.check()) {
        const openvdb::FloatGrid& grid = asFloat();
        return volumeOf(grid.deepCopy()); // meshVolume changes its volume: the caller's grid stays as it is
    }
    if (bp::extract<openvdb::DoubleGrid&> asDouble(o); asDouble.check()) {
        const openvdb::DoubleGrid& d = asDouble();
        auto grid = openvdb::FloatGrid::create(openvdb::FloatTree::Ptr(new openvdb::FloatTree(d.tree())));
        grid->setTransform(d.transform().copy());
        grid->setName(d.getName());
        grid->setGridClass(d.getGridClass());
        return volumeOf(grid);
    }
    throw std::invalid_argument("volume: a pyopenvdb " + type + " is not a scalar grid (need a FloatGrid or DoubleGrid)");
#else
    throw std::invalid_argument("volume: this riemesh was built without Boost.Python and cannot read the pyopenvdb " + type +
                                " directly; pass a numpy array (grid.copyToArray) instead");
#endif
}

} // namespace riemesh::python
