// isotope._isotope: the Python face of the library (isotope/isotope.h), wrapped by the
// isotope package. What it adds to the C++ API, and only that:
// - numpy arrays a[z, y, x] as volumes: float32 C-contiguous ones read where they are
//   (Volume::borrowed, the array held alive by the Python object), other dtypes converted once;
// - meshes as numpy views of the C++ arrays, without a copy;
// - the GIL released while the library works, which it does on a thread of its own, so that the
//   calling thread can hear Ctrl-C (Python handles signals on the main thread only) and cancel;
// - progress reported to a Python callable; an exception it raises cancels the work and is raised;
// - the library's exceptions as Python's, with the library's words: IoError (an OSError),
//   OptionError (a ValueError) naming the option, ValueError, RuntimeError (a Source used from its own
//   progress callback, refused rather than waiting for itself).
// Options are set from Python's values as they are (numbers as numbers), through the setters every
// face uses (option_text), so that a value is refused in the command's words.
#include <oneapi/tbb/global_control.h>
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstring>
#include <exception>
#include <functional>
#include <future>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <set>
#include <span>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "tools/support/option_text.h"
#include "tools/support/stats_fields.h"
#include <isotope/isotope.h>

namespace py = pybind11;

namespace isotope::python {
namespace {

// The options by name as Python gives them: numbers, names (str), a focus point.
using GivenOptions = std::vector<std::pair<std::string, py::object>>;

// Each value set as it is, a number as a number: refused in the words the command uses for the
// same value typed (option_text), and checked together as the command checks them.
ExtractOptions options_of(const GivenOptions& given) {
  const auto shown = [](const py::handle& v) { return py::repr(v).cast<std::string>().substr(0, 64); };
  const auto is_number = [](const py::handle& v) {
    return !py::isinstance<py::bool_>(v) && (py::isinstance<py::int_>(v) || py::isinstance<py::float_>(v) ||
                                             (PyNumber_Check(v.ptr()) && !PyComplex_Check(v.ptr())));
  };
  ExtractOptions o;
  std::set<std::string> names;
  for (const auto& [name, value] : given) {
    names.insert(name);
    if (py::isinstance<py::str>(value)) {  // a name, or a number as a user types it ("1/64")
      const std::string text = value.cast<std::string>();
      if (text.size() > kMaxOptionTextChars) throw OptionError(name, "is too long");  // as the command's reader
      set_extract_option(o, name, std::string_view(text));
    } else if (name == "focus") {
      if (!py::isinstance<py::sequence>(value) || py::len(value) != 3)
        throw OptionError(name, "must be three numbers X,Y,Z, got " + shown(value));
      const py::sequence xyz = value.cast<py::sequence>();
      if (py::isinstance<py::str>(xyz[0]) || py::isinstance<py::str>(xyz[1]) || py::isinstance<py::str>(xyz[2])) {
        const std::string text = py::str(",")
                                     .attr("join")(py::make_tuple(py::str(xyz[0]), py::str(xyz[1]), py::str(xyz[2])))
                                     .cast<std::string>();
        set_extract_option(o, name, std::string_view(text));  // as typed: "1/2,3,4"
        continue;
      }
      std::array<double, 3> p{};
      for (size_t a = 0; a < 3; ++a) {
        const py::object x = xyz[a];
        if (!is_number(x)) throw OptionError(name, "must be three numbers X,Y,Z, got " + shown(value));
        p[a] = PyFloat_AsDouble(x.ptr());  // an integer beyond the doubles: -1 and an OverflowError
        if (PyErr_Occurred()) throw py::error_already_set();
      }
      set_extract_focus(o, p);
    } else if (!is_number(value)) {
      throw OptionError(name, std::string(py::isinstance<py::bool_>(value) ? "must be a number or a name, got "
                                                                           : "must be a number, got ") +
                                  shown(value));
    } else if (py::isinstance<py::int_>(value)) {
      int overflow = 0;
      const long long v = PyLong_AsLongLongAndOverflow(value.ptr(), &overflow);
      if (overflow != 0)  // beyond 64 bits: as its decimal text, which the command refuses or reads alike
        set_extract_option(o, name, std::string_view(py::str(value).cast<std::string>()));
      else
        set_extract_option(o, name, static_cast<int64_t>(v));
    } else {
      set_extract_option(o, name, py::float_(value).cast<double>());
    }
  }
  finish_extract_options(o, names);
  return o;
}

// ---- work off the GIL, cancellable from Python ----

// What a run shares with its callbacks: the cancel flag the library polls, and the first Python
// exception a callback raised.
struct RunState {
  std::atomic<bool> cancel{false};
  std::mutex error_mutex;
  std::optional<py::error_already_set> error;
};

// A Python callable as a ProgressCallback: called under the GIL from whatever thread reports.
// CALLBACK is held by pointer (it outlives the run: a PySource member or an argument of the call),
// so that the library may copy the std::function on any thread without touching a reference count.
// STATE is shared, so that no copy of the callback the library keeps outlives it.
ProgressCallback progress_of(const py::object& callback, const std::shared_ptr<RunState>& shared) {
  if (callback.is_none()) return {};
  return [callback = &callback, shared](double fraction) {
    RunState& state = *shared;
    if (state.cancel.load()) return;
    py::gil_scoped_acquire gil;
    try {
      (*callback)(fraction);
    } catch (py::error_already_set& e) {
      const std::lock_guard lock(state.error_mutex);
      if (!state.error) state.error.emplace(std::move(e));
      state.cancel = true;
    }
  };
}

// The thread the library's work runs on, one per calling Python thread, kept while that thread
// lives: a fresh thread per call would start with a cold malloc arena and a cold oneTBB slot, which
// cost bolt's 4 ms extraction 2 ms and its 42 ms coarse one 11 ms (the bench's Python overhead script).
class Worker {
 public:
  Worker() {
    std::thread([this] { loop(); }).detach();
  }
  void submit(std::function<void()> job) {
    const std::lock_guard lock(mutex_);
    job_ = std::move(job);
    wake_.notify_one();
  }
  // The thread ends after any job in hand and deletes this (nothing joins a detached thread).
  void stop() {
    const std::lock_guard lock(mutex_);
    stop_ = true;
    wake_.notify_one();
  }

 private:
  void loop() {
    for (;;) {
      std::function<void()> job;
      {
        std::unique_lock lock(mutex_);
        wake_.wait(lock, [&] { return job_ != nullptr || stop_; });
        if (!job_) break;
        job = std::exchange(job_, nullptr);
      }
      job();
    }
    delete this;
  }
  std::mutex mutex_;
  std::condition_variable wake_;
  std::function<void()> job_;
  bool stop_ = false;
};

// This thread's worker: stopped when the thread ends, made again in a forked child (which inherits
// the pointer but not the thread: multiprocessing forks on Linux).
Worker& worker() {
  struct Handle {
    Worker* worker = nullptr;
    pid_t pid = 0;
    ~Handle() {
      if (worker != nullptr && pid == ::getpid()) worker->stop();
    }
  };
  thread_local Handle handle;
  if (handle.worker == nullptr || handle.pid != ::getpid()) {
    handle.worker = new Worker;
    handle.pid = ::getpid();
  }
  return *handle.worker;
}

// Runs WORK on this thread's worker with the GIL released, and waits for it here, checking for
// signals every 50 ms: Ctrl-C sets the cancel flag (the library stops at its next piece or tile)
// and raises KeyboardInterrupt once the work has stopped. THREADS > 0 bounds the library's threads.
template <typename Work>
auto run(RunState& state, int threads, Work work) -> decltype(work()) {
  using Result = decltype(work());
  // Shared with the worker's copy of the job, so that neither thread frees it under the other.
  const auto task = std::make_shared<std::packaged_task<Result()>>([&]() -> Result {
    std::optional<tbb::global_control> limit;
    if (threads > 0) limit.emplace(tbb::global_control::max_allowed_parallelism, static_cast<size_t>(threads));
    return work();
  });
  std::future<Result> done = task->get_future();
  {
    py::gil_scoped_release release;
    worker().submit([task] { (*task)(); });
  }
  bool interrupted = false;
  while (true) {
    {
      py::gil_scoped_release release;
      if (done.wait_for(std::chrono::milliseconds(50)) == std::future_status::ready) break;
    }
    if (!interrupted && PyErr_CheckSignals() != 0) {  // a handler raised (KeyboardInterrupt): stop
      interrupted = true;
      state.cancel = true;
    }
  }
  if (interrupted) {
    try {
      done.get();
    } catch (...) {  // the cancellation's own exception: the signal's is the one to raise
    }
    throw py::error_already_set();
  }
  try {
    Result result = done.get();
    // A callback that raised at its last report, or during a step that cannot be cancelled (the
    // hierarchy's build), still has its exception raised.
    if (state.error) throw std::move(*state.error);
    return result;
  } catch (const ExtractionCancelled&) {
    if (state.error) throw std::move(*state.error);
    throw;
  } catch (const IoError&) {
    if (state.error) throw std::move(*state.error);  // convert's cancellation is an IoError
    throw;
  }
}

// ---- arrays as volumes ----

// A numpy array a[z, y, x] as a Volume: float32 in C order is borrowed (ARRAY must outlive the
// Volume; the caller keeps it), any other supported dtype or layout converted to float32 once.
Volume volume_of(const py::array& array, const std::optional<std::array<double, 3>>& spacing,
                 const std::optional<std::array<double, 3>>& origin, py::object& keep_alive) {
  if (array.ndim() != 3)
    throw py::value_error("a volume is a 3-D array a[z, y, x], got " + std::to_string(array.ndim()) + " dimensions");
  const std::string kind = py::str(array.dtype()).cast<std::string>();
  static const std::vector<std::string> kSupported = {"uint8", "uint16", "int16", "float32", "float64"};
  if (std::find(kSupported.begin(), kSupported.end(), kind) == kSupported.end())
    throw py::type_error("isotope reads arrays of uint8, uint16, int16, float32 and float64, got " + kind +
                         " (convert it with a.astype(numpy.float32))");
  using Floats = py::array_t<float, py::array::c_style | py::array::forcecast>;
  // The same array when it is float32 in C order and aligned, else a copy. Not Floats::ensure,
  // which clears the error of a failed copy (a MemoryError) and leaves nothing to raise: this
  // constructor raises it.
  const bool aligned = (array.flags() & py::detail::npy_api::NPY_ARRAY_ALIGNED_) != 0;
  Floats floats(aligned ? py::object(array) : array.attr("copy")());
  keep_alive = floats;
  Volume v;
  v.dims = {floats.shape(2), floats.shape(1), floats.shape(0)};
  if (spacing) v.spacing = *spacing;
  if (origin) v.origin = *origin;
  v.borrowed = std::span<const float>(floats.data(), static_cast<size_t>(floats.size()));
  return v;
}

VolumeSpec spec_of(const std::string& path, const std::optional<std::string>& dims,
                   const std::optional<std::string>& type) {
  VolumeSpec spec;
  spec.path = path;
  if (dims) {  // "XxYxZ", read as the command reads --dims
    spec.dims = parse_dims(*dims);
    if (!spec.dims) throw OptionError("dims", "must look like 64x64x32, got '" + dims->substr(0, 128) + "'");
  }
  if (type) {
    spec.type = parse_scalar_type(*type);
    if (!spec.type) throw OptionError("type", "must be uint8, uint16, int16, float32 or float64, got '" + *type + "'");
  }
  return spec;
}

// ---- meshes ----

// A mesh and what was measured of it; the numpy arrays are views of its memory.
struct PyMesh {
  Mesh mesh;
  py::dict stats;
  std::optional<py::array_t<float>> normals;  // computed on first use
};

template <typename T>
py::array_t<T> view(const T* data, size_t rows, const py::object& owner) {
  if (rows == 0) return py::array_t<T>(std::vector<py::ssize_t>{0, 3});
  // Read-only: an index written out of range would make normals(), topology() and save() read
  // outside the mesh (and save() runs without the GIL). Copy to edit: mesh.faces.copy().
  py::array_t<T> a =
      py::array_t<T>({static_cast<py::ssize_t>(rows), py::ssize_t{3}},
                     {static_cast<py::ssize_t>(3 * sizeof(T)), static_cast<py::ssize_t>(sizeof(T))}, data, owner);
  a.attr("setflags")(py::arg("write") = false);
  return a;
}

py::dict stats_dict(const Mesh& mesh, const ExtractStats& s) {
  py::dict d;
  d["vertices"] = mesh.positions.size();
  d["triangles"] = mesh.triangles.size();
  const auto put = [&d](const char* name, const auto& value) { d[name] = value; };
  tools::for_each_work_stat(s, put);
  tools::for_each_budget_stat(s, put);
  tools::for_each_delta_stat(s, put);
  return d;
}

py::dict info_dict(const SourceInfo& i) {
  py::dict d;
  d["store"] = i.store;
  d["dims"] = i.dims;
  d["shape"] = py::make_tuple(i.dims[2], i.dims[1], i.dims[0]);  // as numpy indexes it
  d["spacing"] = i.spacing;
  d["origin"] = i.origin;
  d["lattice_k"] = i.lattice_k;
  d["read_seconds"] = i.read_seconds;
  d["preprocess_seconds"] = i.preprocess_seconds;
  d["hierarchy_built"] = i.hierarchy_built;
  d["values_in_memory"] = i.values_in_memory;
  d["critical_counted"] = i.critical_counted;
  d["critical_paper"] = i.critical_counted ? py::cast(i.critical_paper) : py::none();
  d["critical_exact"] = i.critical_counted ? py::cast(i.critical_exact) : py::none();
  d["input_bytes"] = i.input_bytes;
  d["store_bytes"] = i.store_bytes;
  d["cache_mb"] = i.cache_mb;
  d["bytes_read"] = i.bytes_read;
  d["bricks_read"] = i.bricks_read;
  d["cache_hits"] = i.cache_hits;
  d["read_waits"] = i.read_waits;
  d["read_hints"] = i.read_hints;
  return d;
}

// ---- sources ----

// An opened input (isotope::Source) and the array it may borrow from.
class PySource {
 public:
  PySource(const py::object& input, const std::optional<std::string>& dims, const std::optional<std::string>& type,
           const std::optional<std::array<double, 3>>& spacing, const std::optional<std::array<double, 3>>& origin,
           int64_t cache_mb, const py::object& progress)
      : progress_(progress) {
    OpenOptions options;
    options.cache_mb = cache_mb;
    if (py::isinstance<py::array>(input)) {
      if (dims || type) throw OptionError("dims", "is for raw files, not arrays (an array has its shape and dtype)");
      Volume v = volume_of(input.cast<py::array>(), spacing, origin, array_);
      source_ = std::make_shared<Source>(open_volume(std::move(v), options));
    } else {
      if (spacing || origin)
        throw OptionError("spacing", "is for arrays; a file's header (NRRD, HDF5, a store) gives its geometry");
      const VolumeSpec spec = spec_of(py::str(input).cast<std::string>(), dims, type);  // str or os.PathLike
      RunState state;
      source_ = run(state, 0, [&] { return std::make_shared<Source>(open_volume(spec, options)); });
    }
  }

  py::object extract(const GivenOptions& given, const std::string& threads_text) {
    refuse_reentry();
    const ExtractOptions options = options_of(given);
    const int threads = parse_thread_count(threads_text);
    const auto shared = std::make_shared<RunState>();
    RunState& state = *shared;
    RunContext context;
    context.cancel = &state.cancel;
    // The build of the hierarchy, when this extraction is the one that builds it (none: it counts nothing).
    if (ProgressCallback report = progress_of(progress_, shared))
      context.progress = [this, report = std::move(report)](double f) {
        const Reporting reporting(this);
        report(f);
      };
    ExtractStats stats;
    auto result = std::make_unique<PyMesh>();
    result->mesh = run(state, threads, [&] { return source_->extract(options, context, &stats); });
    result->stats = stats_dict(result->mesh, stats);
    return py::cast(std::move(result));
  }

  py::dict info() const {
    refuse_reentry();
    SourceInfo i;
    {  // it waits for a hierarchy being built, whose progress callback may wait for the GIL
      py::gil_scoped_release release;
      i = source_->info();
    }
    return info_dict(i);
  }

 private:
  // The source whose hierarchy's build is reporting on this thread, if any: its progress callback
  // runs while the build holds the source, so a callback that uses the same Source (its info, an
  // extraction) would wait for itself forever.
  static inline thread_local const PySource* reporting_ = nullptr;
  struct Reporting {
    const PySource* previous;
    explicit Reporting(const PySource* source) : previous(std::exchange(reporting_, source)) {}
    ~Reporting() { reporting_ = previous; }
  };
  void refuse_reentry() const {
    if (reporting_ == this)
      throw std::runtime_error(
          "a progress callback may not use the Source that reports to it (its hierarchy is being built); use "
          "the Source after the call that builds it returns");
  }

  py::object array_;     // the array a volume borrows, if any
  py::object progress_;  // a Python callable or None
  std::shared_ptr<Source> source_;
};

py::dict convert_any(const py::object& input, const std::string& output, const std::optional<std::string>& dims,
                     const std::optional<std::string>& type, const std::optional<std::array<double, 3>>& spacing,
                     const std::optional<std::array<double, 3>>& origin, int64_t memory_mb, int64_t zstd_level,
                     int64_t brick_bits, int64_t quantize_bits, const std::string& threads_text,
                     const py::object& progress) {
  const int threads = parse_thread_count(threads_text);
  const auto shared = std::make_shared<RunState>();
  RunState& state = *shared;
  // Any 64-bit value taken, clamped into the options' ints: the library refuses it there, by name.
  const auto small = [](int64_t v) {
    return static_cast<int>(std::clamp<int64_t>(v, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
  };
  ConvertOptions options;
  options.memory_mb = memory_mb;
  options.zstd_level = small(zstd_level);
  options.brick_bits = small(brick_bits);
  options.quantize_bits = small(quantize_bits);
  RunContext context;
  context.progress = progress_of(progress, shared);
  context.cancel = &state.cancel;
  ConvertStats s;
  if (py::isinstance<py::array>(input)) {
    py::object keep;
    const Volume v = volume_of(input.cast<py::array>(), spacing, origin, keep);
    s = run(state, threads, [&] { return convert(v, output, options, context); });
  } else {
    const VolumeSpec spec = spec_of(py::str(input).cast<std::string>(), dims, type);
    s = run(state, threads, [&] { return convert(spec, output, options, context); });
  }
  py::dict d;
  d["dims"] = s.dims;
  d["type"] = s.type;
  d["seconds"] = s.seconds;
  d["input_bytes"] = s.input_bytes;
  d["output_bytes"] = s.output_bytes;
  d["bricks"] = s.bricks;
  return d;
}

}  // namespace
}  // namespace isotope::python

PYBIND11_MODULE(_isotope, m) {
  using namespace isotope;
  using namespace isotope::python;
  m.doc() = "isotope's C++ library; use the isotope package (python/isotope/__init__.py)";
  m.attr("__version__") = ISOTOPE_VERSION_STRING;
  // The library's defaults, for the package's signatures: one value per default (isotope/source.h,
  // isotope/convert.h).
  m.attr("DEFAULT_CACHE_MB") = OpenOptions{}.cache_mb;
  m.attr("DEFAULT_MEMORY_MB") = ConvertOptions{}.memory_mb;
  m.attr("DEFAULT_ZSTD_LEVEL") = ConvertOptions{}.zstd_level;
  m.attr("DEFAULT_BRICK_BITS") = ConvertOptions{}.brick_bits;

  static py::exception<IoError> io_error(m, "IoError", PyExc_OSError);
  static py::exception<OptionError> option_error(m, "OptionError", PyExc_ValueError);
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const OptionError& e) {
      py::object error = py::handle(option_error.ptr())(e.what());  // an instance, to carry .option
      error.attr("option") = e.option;
      PyErr_SetObject(option_error.ptr(), error.ptr());
    } catch (const InvalidInput& e) {
      PyErr_SetString(PyExc_ValueError, e.what());
    } catch (const IoError& e) {
      io_error(e.what());
    } catch (const ExtractionCancelled& e) {
      PyErr_SetString(PyExc_RuntimeError, e.what());
    }
  });

  py::class_<PyMesh>(m, "Mesh", "A triangle mesh: numpy views of the library's arrays")
      .def_property_readonly(
          "vertices",
          [](py::object self) {
            const Mesh& mesh = self.cast<PyMesh&>().mesh;
            return view(reinterpret_cast<const float*>(mesh.positions.data()), mesh.positions.size(), self);
          },
          "(n, 3) float32: x, y, z of each vertex, in physical coordinates (origin + spacing * index)")
      .def_property_readonly(
          "faces",
          [](py::object self) {
            const Mesh& mesh = self.cast<PyMesh&>().mesh;
            return view(reinterpret_cast<const uint32_t*>(mesh.triangles.data()), mesh.triangles.size(), self);
          },
          "(m, 3) uint32: vertex indices of each triangle, counter-clockwise seen from outside (values <= iso)")
      .def_property_readonly(
          "normals",
          [](PyMesh& self) {
            if (!self.normals) {
              const auto n = vertex_normals(self.mesh);
              py::array_t<float> a({static_cast<py::ssize_t>(n.size()), py::ssize_t{3}});
              if (!n.empty()) std::memcpy(a.mutable_data(), n.data(), n.size() * sizeof(n[0]));
              self.normals = a;
            }
            return *self.normals;
          },
          "(n, 3) float32: unit normal of each vertex, outward (area-weighted over its triangles)")
      .def_readonly("stats", &PyMesh::stats, "what the extraction measured of itself")
      .def(
          "save",
          [](const PyMesh& self, const py::object& path) {
            const std::string p = py::str(path).cast<std::string>();
            py::gil_scoped_release release;
            write_mesh(self.mesh, p);
          },
          py::arg("path"), "Writes the mesh, its format by extension: .ply, .obj, .stl, .glb or .vtp (atomically)")
      .def(
          "topology",
          [](const PyMesh& self) {
            MeshTopology t;
            {
              py::gil_scoped_release release;
              t = measure_topology(self.mesh);
            }
            py::dict d;
            d["vertices"] = t.vertices;
            d["triangles"] = t.triangles;
            d["edges"] = t.edges;
            d["components"] = t.components;
            d["euler_characteristic"] = t.euler_characteristic;
            d["boundary_edges"] = t.boundary_edges;
            d["nonmanifold_edges"] = t.nonmanifold_edges;
            return d;
          },
          "Components, Euler characteristic, boundary and non-manifold edges");

  py::class_<PySource>(m, "Source")
      .def(py::init<const py::object&, const std::optional<std::string>&, const std::optional<std::string>&,
                    const std::optional<std::array<double, 3>>&, const std::optional<std::array<double, 3>>&, int64_t,
                    const py::object&>(),
           py::arg("input"), py::arg("dims"), py::arg("type"), py::arg("spacing"), py::arg("origin"),
           py::arg("cache_mb"), py::arg("progress"))
      .def("extract", &PySource::extract, py::arg("options"), py::arg("threads"))
      .def_property_readonly("info", &PySource::info);

  m.def("convert", &convert_any, py::arg("input"), py::arg("output"), py::arg("dims"), py::arg("type"),
        py::arg("spacing"), py::arg("origin"), py::arg("memory_mb"), py::arg("zstd_level"), py::arg("brick_bits"),
        py::arg("quantize_bits"), py::arg("threads"), py::arg("progress"));
}
