// The Python module `riemesh` (pybind11): numpy arrays, pyopenvdb grids and image files in, numpy arrays
// out, through the same pipeline as vdb2mesh (riemesh/vdb/pipeline.h). No OpenVDB include here.
#include <pybind11/pybind11.h>
#include <pybind11/numpy.h>
#include <pybind11/stl.h>

#include "pyopenvdb_input.h"

#include "riemesh/mesh_io.h"
#include "riemesh/vdb/pipeline.h"
#include "riemesh/vdb/volume.h"
#include "riemesh/vdb/volume_sources.h"

#include <array>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

namespace py = pybind11;
using namespace riemesh;

namespace {

double secondsSince(std::chrono::steady_clock::time_point t)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - t).count();
}

/// A riemesh.Volume: an image (and, after meshing, its metric) in memory.
struct PyVolume {
    std::shared_ptr<vdb::Volume> volume;
};

py::dict infoDict(const vdb::ImageInfo& info)
{
    py::dict d;
    d["path"] = info.path.empty() ? py::object(py::none()) : py::object(py::str(info.path));
    d["format"] = info.format;
    d["grid"] = info.gridName;
    d["class"] = info.gridClass;
    d["voxel_size"] = info.voxelSize;
    d["dims"] = py::make_tuple(info.dims[0], info.dims[1], info.dims[2]);
    d["active_voxels"] = info.activeVoxels;
    d["min"] = info.minValue;
    d["max"] = info.maxValue;
    const auto& b = info.worldBounds;
    d["world_bounds"] = py::make_tuple(py::make_tuple(b.min()[0], b.min()[1], b.min()[2]),
                                       py::make_tuple(b.max()[0], b.max()[1], b.max()[2]));
    d["world_space"] = info.transformNote;
    return d;
}

/// Turns bad-file errors into Python's: a missing file is FileNotFoundError, anything else about the
/// image ValueError, both with vdb2mesh's message.
[[noreturn]] void raiseReadError(const std::string& path, const std::exception& e)
{
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
        PyErr_SetString(PyExc_FileNotFoundError, e.what());
        throw py::error_already_set();
    }
    throw py::value_error(e.what());
}

vdb::Volume readVolume(const std::string& path, const std::string& grid, std::uint64_t maxMemory)
{
    try {
        py::gil_scoped_release release;
        return vdb::Volume::read(path, grid, maxMemory);
    } catch (const std::bad_alloc&) {
        throw;
    } catch (const std::exception& e) {
        raiseReadError(path, e);
    }
}

std::array<double, 3> triple(const py::handle& value, const char* name)
{
    if (py::isinstance<py::float_>(value) || py::isinstance<py::int_>(value)) {
        const double v = value.cast<double>();
        return {v, v, v};
    }
    const auto seq = py::reinterpret_borrow<py::sequence>(value);
    if (!py::isinstance<py::sequence>(value) || py::len(seq) != 3)
        throw py::value_error(std::string(name) + ": expected a number or 3 numbers");
    return {seq[0].cast<double>(), seq[1].cast<double>(), seq[2].cast<double>()};
}

/// numpy's element type as ours; nullopt for types read through a float32 conversion (float16, bool, ...).
std::optional<vdb::ArrayElement> elementOf(const py::dtype& dt)
{
    const char kind = dt.kind();
    const auto size = dt.itemsize();
    if (kind == 'f' && size == 4) return vdb::ArrayElement::Float32;
    if (kind == 'f' && size == 8) return vdb::ArrayElement::Float64;
    if (kind == 'i' && size == 1) return vdb::ArrayElement::Int8;
    if (kind == 'i' && size == 2) return vdb::ArrayElement::Int16;
    if (kind == 'i' && size == 4) return vdb::ArrayElement::Int32;
    if (kind == 'i' && size == 8) return vdb::ArrayElement::Int64;
    if (kind == 'u' && size == 1) return vdb::ArrayElement::UInt8;
    if (kind == 'u' && size == 2) return vdb::ArrayElement::UInt16;
    if (kind == 'u' && size == 4) return vdb::ArrayElement::UInt32;
    if (kind == 'u' && size == 8) return vdb::ArrayElement::UInt64;
    return std::nullopt;
}

bool nativeByteOrder(const py::dtype& dt)
{
    const char order = dt.attr("byteorder").cast<std::string>()[0];
    return order == '=' || order == '|'; // numpy writes '<' or '>' only for a non-native order
}

/// A Volume from anything numpy takes as a 3D array. Float32, float64 and integer arrays of native
/// byte order are read where they are, whatever their strides (no copy); other element types are
/// converted to float32 first.
vdb::Volume volumeFromArrayLike(const py::handle& object, const py::handle& spacing, const py::handle& origin,
                                const std::string& gridClass, std::uint64_t maxMemory)
{
    py::module_ np = py::module_::import("numpy");
    py::array array = np.attr("asarray")(object);
    if (array.ndim() != 3) {
        std::string shape = "(";
        for (py::ssize_t a = 0; a < array.ndim(); ++a) shape += (a ? ", " : "") + std::to_string(array.shape(a));
        throw py::value_error("volume: expected a 3D array indexed [i, j, k], got shape " + shape +
                              (array.ndim() == 1 ? ",)" : ")"));
    }
    auto element = nativeByteOrder(array.dtype()) ? elementOf(array.dtype()) : std::nullopt;
    if (!element) {
        const char kind = array.dtype().kind();
        if (kind != 'f' && kind != 'i' && kind != 'u' && kind != 'b')
            throw py::value_error("volume: array of dtype " + py::str(array.dtype()).cast<std::string>() +
                                  " is not a real number type");
        array = array.attr("astype")(np.attr("float32"));
        element = vdb::ArrayElement::Float32;
    }
    vdb::ArrayView view;
    view.data = array.data();
    view.element = *element;
    for (int a = 0; a < 3; ++a) {
        view.shape[std::size_t(a)] = array.shape(a);
        view.strides[std::size_t(a)] = array.strides(a);
    }
    vdb::ArrayPlacement placement;
    placement.spacing = triple(spacing, "spacing");
    placement.origin = triple(origin, "origin");
    placement.gridClass = gridClass;
    py::gil_scoped_release release; // `array` stays referenced (and alive) meanwhile
    try {
        return vdb::volumeFromArray(view, placement, maxMemory);
    } catch (const std::runtime_error& e) { // the memory budget: a bad image for this machine
        throw std::invalid_argument(e.what());
    }
}

bool isPath(const py::handle& object)
{
    return py::isinstance<py::str>(object) || py::hasattr(object, "__fspath__");
}

std::string pathOf(const py::handle& object)
{
    return py::module_::import("os").attr("fspath")(object).cast<std::string>();
}

/// The fields of an iteration in the --stats document (PipelineStats' "iterations"), as a dict.
py::dict iterationDict(const IterationStats& s)
{
    py::dict d;
    d["iteration"] = s.iteration;
    d["level"] = s.level;
    d["vertices"] = s.vertices;
    d["mean_kinetic_energy"] = s.meanKineticEnergy;
    d["splits"] = s.splits;
    d["collapses"] = s.collapses;
    d["flips"] = s.flips;
    d["merges"] = s.merges;
    d["cuts"] = s.cuts;
    d["removed_components"] = s.removedComponents;
    d["travelling"] = s.moving;
    d["intersection_free"] = s.intersectionFree;
    d["cut_short"] = s.cutShort;
    d["regularity_redone"] = s.regularityRedone;
    d["ms"] = s.milliseconds;
    return d;
}

/// The pipeline's progress callback while the GIL is released: every 50 ms (and at every stage) it
/// takes the GIL back briefly to let Python handle signals (Ctrl-C: KeyboardInterrupt); with a user
/// callback, it calls it after every iteration with that iteration's dict (False stops the evolution).
struct PythonProgress {
    py::object callback; ///< None or a callable
    std::optional<py::error_already_set> error;
    bool stoppedByCallback = false;
    std::chrono::steady_clock::time_point lastCheck = std::chrono::steady_clock::now();

    bool operator()(vdb::PipelineStage, const IterationStats* s)
    {
        const bool call = s && !callback.is_none();
        const auto now = std::chrono::steady_clock::now();
        if (!call && s && now - lastCheck < std::chrono::milliseconds(50)) return true;
        lastCheck = now;
        py::gil_scoped_acquire gil;
        if (PyErr_CheckSignals() != 0) {
            error.emplace();
            return false;
        }
        if (!call) return true;
        try {
            const py::object answer = callback(iterationDict(*s));
            if (answer.ptr() == Py_False) {
                stoppedByCallback = true;
                return false;
            }
        } catch (py::error_already_set& e) {
            error.emplace(std::move(e));
            return false;
        }
        return true;
    }
};

/// riemesh.Mesh: the result.
struct PyMesh {
    std::shared_ptr<const Mesh> mesh;
    std::shared_ptr<const vdb::Volume> placement; ///< the image's transform, for .save("x.vdb")
    std::string comment;
    py::array_t<double> vertices;
    py::array_t<std::int32_t> faces;
    py::object stats;
    MeshTopology topology;
    std::size_t selfIntersections = 0;

    void save(const std::string& path) const
    {
        py::gil_scoped_release release;
        if (vdb::fileExtension(path) == ".vdb") {
            placement->writeSurfaceLevelSet(path, *mesh);
            return;
        }
        try {
            meshFormatFromPath(path);
        } catch (const std::invalid_argument& e) {
            throw std::invalid_argument(std::string(e.what()) + " (or .vdb for a level set)");
        }
        writeMesh(path, *mesh, comment);
    }
};

/// Live vertices in index order and faces oriented outward, as the mesh files hold them.
void fillArrays(PyMesh& out, const Mesh& mesh)
{
    std::vector<std::int64_t> map(mesh.n_vertices(), -1);
    std::size_t nv = 0, nf = 0;
    for (auto v : mesh.vertices()) map[std::size_t(v.idx())] = std::int64_t(nv++);
    for (auto f : mesh.faces()) (void)f, ++nf;
    out.vertices = py::array_t<double>({py::ssize_t(nv), py::ssize_t(3)});
    out.faces = py::array_t<std::int32_t>({py::ssize_t(nf), py::ssize_t(3)});
    auto V = out.vertices.mutable_unchecked<2>();
    auto F = out.faces.mutable_unchecked<2>();
    py::ssize_t i = 0;
    for (auto v : mesh.vertices()) {
        const Vec3 p = position(mesh, v);
        for (int a = 0; a < 3; ++a) V(i, a) = p[a];
        ++i;
    }
    const bool flip = signedVolume(mesh) < 0;
    i = 0;
    for (auto f : mesh.faces()) {
        int k = 0;
        std::int32_t t[3] = {0, 0, 0};
        for (auto v : mesh.fv_range(f))
            if (k < 3) t[k++] = std::int32_t(map[std::size_t(v.idx())]);
        if (flip) std::swap(t[1], t[2]);
        for (int a = 0; a < 3; ++a) F(i, a) = t[a];
        ++i;
    }
    out.vertices.attr("setflags")(py::arg("write") = false);
    out.faces.attr("setflags")(py::arg("write") = false);
}

PyMesh meshPy(const py::object& volumeArg, std::optional<double> iso, const py::object& spacing, const py::object& origin,
              const std::string& gridClass, const std::string& grid, const std::string& metric, double delta, double zeta,
              double muMax, double sigma, double rho, double edgeGain, std::optional<double> smooth, int maxIterations,
              std::uint64_t maxVertices, const std::string& init, bool openBorders, int downsample, int levels, int threads,
              std::uint64_t maxMemory, bool intersectionFree, bool sharpen, bool faceSamples, const py::object& progress)
{
    const auto start = std::chrono::steady_clock::now();
    vdb::PipelineOptions options;
    options.iso = iso;
    if (metric == "riemannian") options.riemannian = true;
    else if (metric == "euclidean") options.riemannian = false;
    else throw py::value_error("--metric: '" + metric + "' is not riemannian or euclidean");
    options.delta = delta;
    options.zeta = zeta;
    options.muMax = muMax;
    options.sigma = sigma;
    options.rho = rho;
    options.tangentialGain = edgeGain;
    options.smooth = smooth;
    options.maxIterations = maxIterations;
    options.maxVertices = maxVertices;
    options.openBorders = openBorders;
    options.downsample = downsample;
    options.levels = levels;
    options.threads = threads;
    options.intersectionFree = intersectionFree;
    options.sharpen = sharpen;
    options.faceSamples = faceSamples;
    options.init = vdb::parseInitialSurface(init);
    vdb::checkPipelineOptions(options); // before any long work
    if (!progress.is_none() && !PyCallable_Check(progress.ptr())) throw py::type_error("progress: must be callable or None");

    // The volume: a copy of a riemesh.Volume (meshing changes it), a file, a pyopenvdb grid or an array.
    std::optional<vdb::Volume> volume;
    std::optional<std::string> input;
    bool arrayInput = false, pathInput = false;
    if (py::isinstance<PyVolume>(volumeArg)) {
        const auto& v = *volumeArg.cast<const PyVolume&>().volume;
        py::gil_scoped_release release;
        volume = v.copy();
        if (!v.info().path.empty()) input = v.info().path;
    } else if (isPath(volumeArg)) {
        pathInput = true;
        input = pathOf(volumeArg);
        volume = readVolume(*input, grid, maxMemory);
    } else if (auto fromGrid = python::volumeFromPyOpenVDB(volumeArg.ptr())) {
        volume = std::move(*fromGrid);
    } else {
        volume = volumeFromArrayLike(volumeArg, spacing, origin, gridClass, maxMemory);
        arrayInput = true;
    }
    if (!arrayInput) {
        const auto s = triple(spacing, "spacing"), o = triple(origin, "origin");
        if (s != std::array<double, 3>{1, 1, 1} || o != std::array<double, 3>{0, 0, 0} || gridClass != "unknown")
            throw py::value_error("spacing, origin and grid_class apply to arrays only: this volume has its own transform "
                                  "and class");
    }
    if (!grid.empty() && !pathInput)
        throw py::value_error("grid: applies to a .vdb or .nvdb file path only");
    const double readSeconds = secondsSince(start);

    PythonProgress watcher;
    watcher.callback = progress;
    options.progress = std::ref(watcher);
    vdb::PipelineResult result;
    {
        py::gil_scoped_release release;
        result = vdb::meshVolume(*volume, options);
        if (watcher.stoppedByCallback && !watcher.error) vdb::analyseResult(result);
    }
    if (watcher.error) throw std::move(*watcher.error); // KeyboardInterrupt, or the callback's exception
    if (result.stop == StopReason::Interrupted && !watcher.stoppedByCallback)
        throw std::runtime_error("meshing was interrupted"); // (not reached: only Python stops it)

    PyMesh out;
    fillArrays(out, result.mesh);
    out.topology = result.topology;
    out.selfIntersections = result.selfIntersections;
    out.comment = "riemesh (Python) from " + (input ? std::filesystem::path(*input).filename().string()
                                                    : result.image.format) +
                  "; world space: " + result.image.transformNote;
    vdb::PipelineRecord record;
    record.input = input;
    record.readSeconds = readSeconds;
    record.totalSeconds = secondsSince(start);
    out.stats = py::module_::import("json").attr("loads")(vdb::pipelineStatsJson(result, record));
    out.placement = std::make_shared<const vdb::Volume>(volume->placement());
    out.mesh = std::make_shared<const Mesh>(std::move(result.mesh));
    return out;
}

} // namespace

PYBIND11_MODULE(riemesh, m)
{
    m.doc() = R"doc(Surfaces from 3D images with the adaptive deformable model of Taton & Lachaud (2003).

riemesh.mesh(volume, iso) meshes a numpy array (indexed volume[i, j, k] as in scikit-image), a pyopenvdb
FloatGrid, a riemesh.Volume or an image file (.vdb .nvdb .nii .nii.gz) with the same pipeline and
defaults as the vdb2mesh command: a closed, oriented triangle mesh with the object's topology, sampled
regularly in a Riemannian metric from the image's structure tensor.)doc";

    py::class_<PyVolume>(m, "Volume", R"doc(An image in memory: from read_volume(), phantom() or an array.

Volume(array, spacing=(1, 1, 1), origin=(0, 0, 0), grid_class='unknown') makes one from a 3D array
indexed [i, j, k]: voxel (i, j, k) sits at world origin + spacing * (i, j, k).)doc")
        .def(py::init([](const py::object& array, const py::object& spacing, const py::object& origin,
                         const std::string& gridClass, std::uint64_t maxMemory) {
                 return PyVolume{std::make_shared<vdb::Volume>(volumeFromArrayLike(array, spacing, origin, gridClass, maxMemory))};
             }),
             py::arg("array"), py::arg("spacing") = py::make_tuple(1, 1, 1), py::arg("origin") = py::make_tuple(0, 0, 0),
             py::arg("grid_class") = "unknown", py::arg("max_memory") = 0)
        .def_property_readonly("info", [](const PyVolume& v) { return infoDict(v.volume->info()); },
                               "The image: path, format, grid, class, voxel_size, dims (active box), active_voxels, "
                               "min, max, world_bounds, world_space.")
        .def("copy", [](const PyVolume& v) { return PyVolume{std::make_shared<vdb::Volume>(v.volume->copy())}; },
             "A deep copy.")
        .def("__repr__", [](const PyVolume& v) {
            const auto& i = v.volume->info();
            return "<riemesh.Volume " + i.format + " '" + i.gridName + "' (" + i.gridClass + ") " + std::to_string(i.dims[0]) +
                   "x" + std::to_string(i.dims[1]) + "x" + std::to_string(i.dims[2]) + ">";
        });

    py::class_<PyMesh>(m, "Mesh", "The result of riemesh.mesh(): a closed triangle mesh in world units, outward.")
        .def_readonly("vertices", &PyMesh::vertices, "N x 3 float64 vertex positions, world units (read-only).")
        .def_readonly("faces", &PyMesh::faces, "M x 3 int32 vertex indices per triangle, counter-clockwise seen from "
                                               "outside (read-only).")
        .def_readonly("stats", &PyMesh::stats, "vdb2mesh's --stats document as a dict: image, parameters, metric, "
                                               "iterations (one dict each), summary (components, genus, "
                                               "self_intersections, iterations, stop, timings), input, output.")
        .def("save", [](const PyMesh& m, const py::object& path) { m.save(pathOf(path)); }, py::arg("path"),
             "Writes the mesh by extension: .obj .ply .off .stl (outward normals), or .vdb (a level set "
             "'surface' with the image's transform); through a temporary file, renamed when complete.")
        .def("__repr__", [](const PyMesh& p) {
            const auto& t = p.topology;
            return "<riemesh.Mesh " + std::to_string(t.vertices) + " vertices, " + std::to_string(t.faces) + " faces, " +
                   std::to_string(t.components) + " component" + (t.components == 1 ? "" : "s") + ", genus " +
                   std::to_string(t.genus) + ">";
        });

    m.def("read_volume",
          [](const py::object& path, const std::string& grid, std::uint64_t maxMemory) {
              return PyVolume{std::make_shared<vdb::Volume>(readVolume(pathOf(path), grid, maxMemory))};
          },
          py::arg("path"), py::arg("grid") = "", py::arg("max_memory") = 0,
          R"doc(Reads an image: .vdb (grid `grid`, default the first scalar grid), .nvdb, .nii or .nii.gz, with its
world transform (NIfTI: scanner space from the sform/qform). max_memory: bytes (0: half the physical
memory); an image box needing more is refused before its voxels are read. Raises FileNotFoundError for
a missing file and ValueError for a bad one, with vdb2mesh's messages.)doc");

    m.def("phantom",
          [](const std::string& name, int size, double noise, std::uint64_t seed, const std::string& grid) {
              py::gil_scoped_release release;
              return PyVolume{std::make_shared<vdb::Volume>(vdb::phantomVolume(name, size, noise, seed, grid))};
          },
          py::arg("name"), py::arg("size") = 100, py::arg("noise") = 0.5, py::arg("seed") = 1, py::arg("grid") = "density",
          R"doc(A synthetic volume of size^3 unit voxels (world = index), as `vdbphantom NAME --size --noise --seed`
writes it: name is one of phantom_shapes(); grid 'density' (a fog volume with additive Gaussian noise,
0.5 on the true surface) or 'sdf' (its exact signed distance, a level set).)doc");

    m.def("phantom_shapes", &vdb::phantomShapes, "The phantom names.");

    m.def("mesh", &meshPy, py::arg("volume"), py::arg("iso") = py::none(), py::kw_only(),
          py::arg("spacing") = py::make_tuple(1, 1, 1), py::arg("origin") = py::make_tuple(0, 0, 0),
          py::arg("grid_class") = "unknown", py::arg("grid") = "", py::arg("metric") = "riemannian",
          py::arg("delta") = vdb::kDelta, py::arg("zeta") = vdb::kZeta, py::arg("mu_max") = vdb::kMuMax,
          py::arg("sigma") = vdb::kSigma, py::arg("rho") = vdb::kRho, py::arg("edge_gain") = vdb::kTangentialGain,
          py::arg("smooth") = py::none(), py::arg("max_iterations") = vdb::kMaxIterations,
          py::arg("max_vertices") = vdb::kMaxVertices, py::arg("init") = "box", py::arg("open_borders") = false,
          py::arg("downsample") = 1, py::arg("levels") = -1, py::arg("threads") = 0, py::arg("max_memory") = 0,
          py::arg("intersection_free") = false, py::arg("sharpen") = true, py::arg("face_samples") = false, py::arg("progress") = py::none(),
          R"doc(Meshes the isosurface `iso` of `volume` with the adaptive deformable model; returns a riemesh.Mesh.

volume: a 3D numpy array (or anything numpy.asarray takes) indexed [i, j, k] as in scikit-image, its
  voxel (i, j, k) at world origin + spacing * (i, j, k) (float32, float64 and integer arrays of any
  order are read where they are, without a copy; other dtypes are converted to float32 first); a
  pyopenvdb FloatGrid or DoubleGrid (its transform used; copied, never changed); a riemesh.Volume
  (copied); or a file path (.vdb with `grid`, .nvdb, .nii, .nii.gz).
iso: the isovalue, image intensity. Default 0.5 for fog volumes, 0 for level sets (inside negative);
  required for other images (arrays are of class `grid_class`: 'unknown', 'fog' or 'levelset').
The other options are vdb2mesh's flags, with the same defaults and units: metric ('riemannian' or
  'euclidean'), delta (shortest edge, metric length, voxels), zeta, mu_max, sigma and rho (voxels),
  edge_gain, smooth (voxels; default 1 for images, 0 for level sets), max_iterations, max_vertices, init ('box', 'sphere:X,Y,Z,R[;...]' in
  world units, 'mesh:FILE'), open_borders, downsample, levels (-1: automatic), threads,
  max_memory (bytes), intersection_free (no iteration may make faces cross; off by default: it costs
  1.9-2.0x the evolution's time; a surface that crosses itself without it is evolved again with it,
  stats['summary']['untangled_at_iteration'] then says when), sharpen (creases and corners put back on the result where the filtered face normals and the image both turn sharply across an edge; on by default),
  face_samples (the image force sampled at the faces' centres too; off by default).
progress: called after every iteration with that iteration's statistics (a dict, as in
  stats['iterations']); returning False stops the evolution there (stats['summary']['stop'] is then
  'interrupted').
The GIL is released while the volume is prepared and the model evolves; Ctrl-C raises
KeyboardInterrupt. Bad options and images raise ValueError with vdb2mesh's messages.)doc");

    m.attr("has_pyopenvdb") = python::hasPyOpenVDB();
    m.attr("__version__") = "0.1.0";
}
