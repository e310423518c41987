#include "tools/serve/viewer_server.h"

#include <httplib.h>
#include <oneapi/tbb/global_control.h>
#include <sys/socket.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <semaphore>
#include <thread>

#include "engine/core/parallel.h"
#include "io/file/input_file.h"
#include "io/mesh/mesh_wire.h"
#include "io/source_access.h"
#include "io/store/store_histogram.h"
#include "io/store/store_reader.h"
#include "isotope/error.h"
#include "isotope/mesh.h"
#include "isotope/source.h"
#include "tools/serve/bounded_http.h"
#include "tools/serve/serve_request.h"
#include "tools/serve/supersession.h"
#include "tools/serve/viewer_assets.h"
#include "tools/support/command_line.h"
#include "tools/support/peak_memory.h"
#include "tools/support/report.h"

namespace isotope::tools {
namespace {

constexpr int kHistogramBins = 128;
constexpr int64_t kHistogramSamples = int64_t{4} << 20;  // a fraction of a second to read
// Extractions at once. Each already runs on every core, so more would only hold more meshes in
// memory; the others wait, and leave the queue as soon as a newer request supersedes them.
constexpr std::ptrdiff_t kConcurrentExtractions = 2;
// Requests waiting for one of those slots, at most; a request beyond them, or one that has waited
// kMaxWaitSeconds, gets 503 with Retry-After (docs/SERVE.md, "Limits"): the memory and the delay a
// crowd of clients can cause stay bounded (the test Serve.ACrowdIsAnsweredOrRefusedWithBoundedMemory).
constexpr int kWaitingExtractions = 16;
constexpr int kMaxWaitSeconds = 30;
// Requests carry no body (docs/SERVE.md, "Limits"; the others are HttpLimits).
constexpr size_t kMaxBodyBytes = 1024;

void answer_text(httplib::Response& res, int status, const std::string& message) {
  res.status = status;
  res.set_content(message + "\n", "text/plain; charset=utf-8");
}

nlohmann::ordered_json store_info_json(const StoreReader& store) {
  const StoreHeader& h = store.header();
  const ValueHistogram hist = sample_histogram(store, kHistogramBins, kHistogramSamples);
  nlohmann::ordered_json j;
  j["store"] = std::filesystem::path(store.path()).filename().string();
  j["dims"] = h.dims;
  j["spacing"] = h.spacing;
  j["origin"] = h.origin;
  j["value_range"] = {h.value_min, h.value_max};
  j["histogram"] = {
      {"min", hist.min}, {"max", hist.max}, {"counts", hist.counts}, {"sampled", hist.sampled}, {"scale", hist.scale}};
  j["iso"] = hist.mean;
  j["eps"] = 0.01 * (h.value_max - h.value_min);
  return j;
}

// Only a store is served (the viewer pages it; a raw volume would be read whole per server).
Source open_store(const ViewerServer::Settings& s) {
  require_regular_file(s.store, s.store, "an isotope store");  // a missing file, a folder or a FIFO says so
  if (!is_store_file(s.store))
    throw IoError(s.store + ": not an isotope store (isotope serve shows stores; run isotope convert first)");
  OpenOptions options;
  options.cache_mb = s.cache_mb;
  options.tune_allocator = true;
  return open_volume(VolumeSpec{s.store, std::nullopt, std::nullopt}, options);
}

using ExtractionSlots = std::counting_semaphore<kConcurrentExtractions>;
struct SlotRelease {
  ExtractionSlots& slots;
  ~SlotRelease() { slots.release(); }
};

}  // namespace

struct ViewerServer::Impl {
  Settings settings;
  Source input;  // the store, opened once: extractions page it, /api/info reads its header
  std::string info;
  Supersession supersession;
  ExtractionSlots slots{kConcurrentExtractions};
  std::atomic<int> waiting{0};
  socket_t listen_socket = -1;
  ResponseBudget responses;  // the meshes being sent
  MemoryReturner memory;
  BoundedHttpServer http;
  std::mutex log_mutex;
  std::mutex run_mutex;  // listen() and stop() from different threads, in either order
  bool stop_requested = false, listening = false;
  std::atomic<bool> finished{false};

  explicit Impl(const Settings& s)
      : settings(s),
        input(open_store(s)),
        info(store_info_json(*detail::SourceAccess::store(input)).dump()),
        responses(s.response_budget_bytes),
        http(s.limits) {
    http.Get("/api/info", [this](const httplib::Request&, httplib::Response& res) {
      res.set_header("Cache-Control", "no-store");
      res.set_content(info, "application/json");
    });
    http.Get("/api/extract", [this](const httplib::Request& req, httplib::Response& res) { extract(req, res); });
    http.Get(R"(/[^?]*)", [](const httplib::Request& req, httplib::Response& res) {
      const auto asset = viewer_asset(req.path);
      if (!asset) return answer_text(res, 404, "not found");
      // Sent from the program's own bytes, not copied per request.
      set_held_content(res, asset->bytes.data(), asset->bytes.size(), asset->content_type, nullptr);
    });
    const httplib::Server::Handler get_only = [](const httplib::Request&, httplib::Response& res) {
      res.set_header("Allow", "GET, HEAD");
      answer_text(res, 405, "method not allowed: the server answers GET only");
    };
    http.Post(".*", get_only).Put(".*", get_only).Delete(".*", get_only).Patch(".*", get_only).Options(".*", get_only);
    http.set_payload_max_length(kMaxBodyBytes);
    http.set_error_handler([](const httplib::Request&, httplib::Response& res) {
      if (res.body.empty()) answer_text(res, res.status, res.status == 404 ? "not found" : "bad request");
    });
    // httplib's default is SO_REUSEPORT, with which a second server (another user's, even) binds
    // the same port and takes a share of the connections. SO_REUSEADDR only lets a restarted
    // server take its port back from connections still in TIME_WAIT.
    http.set_socket_options([this](socket_t sock) {
      const int yes = 1;
      setsockopt(sock, SOL_SOCKET, SO_REUSEADDR, &yes, sizeof yes);
      listen_socket = sock;
    });
    http.set_exception_handler([](const httplib::Request&, httplib::Response& res, std::exception_ptr) {
      answer_text(res, 500, "internal error");
    });
  }

  void extract(const httplib::Request& req, httplib::Response& res) {
    // Marks the extraction's start and end for the memory returner (it keeps freed memory while
    // extractions run).
    const struct Busy {
      MemoryReturner& m;
      explicit Busy(MemoryReturner& returner) : m(returner) { m.busy(); }
      ~Busy() { m.busy(); }
    } busy{memory};
    const auto start = std::chrono::steady_clock::now();
    res.set_header("Cache-Control", "no-store");
    try {
      ServeRequest r = parse_extract_request(req.params);
      std::optional<Supersession::Ticket> ticket;
      RunContext context;  // a later request of the same client cancels this one
      if (r.seq) {
        ticket.emplace(supersession.enter(r.client, *r.seq));
        context.cancel = ticket->cancel();
      }
      if (responses.exhausted()) return refuse_for_responses(res);
      if (!wait_for_slot(ticket ? &*ticket : nullptr)) {
        res.set_header("Retry-After", "1");
        return answer_text(
            res, 503,
            "busy: " + std::to_string(kWaitingExtractions) + " extractions are waiting already; retry in a moment");
      }
      const SlotRelease slot{slots};
      ExtractionRun run;
      run.input = settings.store;
      run.options = r.options;
      run.threads = static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
      Mesh mesh = input.extract(r.options, context, &run.extract);
      run.extract_seconds = seconds_since(start);
      describe(input.info(), run);
      const auto measure_start = std::chrono::steady_clock::now();
      std::vector<std::array<float, 3>> normals;  // meanwhile, on the other core
      parallel_for(0, 2, [&](int64_t part) {      // under TSan: two std::threads
        if (part == 0)
          run.topology = measure_topology(mesh);
        else
          normals = vertex_normals(mesh);
      });
      run.measure_seconds = seconds_since(measure_start);
      run.peak_rss_mb = static_cast<double>(peak_rss_bytes()) / (1 << 20);
      if (ticket && ticket->superseded()) throw ExtractionCancelled{};
      nlohmann::ordered_json report = report_json(run);
      report["seq"] = r.seq ? nlohmann::ordered_json(*r.seq) : nlohmann::ordered_json(nullptr);
      report["server_seconds"] = seconds_since(start);
      // The body is held, against the budget, until its client has taken it (or the pace of
      // BoundedHttpServer ends the connection): the mesh and normals themselves, sent
      // from where they lie after the wire format's header.
      struct Held {
        std::shared_ptr<void> hold;  // released last, once the body is freed (the release trims)
        Mesh mesh;
        std::vector<std::array<float, 3>> normals;
        MeshWirePieces body;
      };
      auto held = std::make_shared<Held>();
      held->mesh = std::move(mesh);
      held->normals = std::move(normals);
      held->body = mesh_wire_pieces(held->mesh, held->normals, report.dump());
      // Held: the arrays' whole allocations, room reserved beyond their sizes included.
      held->hold = responses.hold(held->body.head.size() +
                                  sizeof(held->mesh.positions[0]) *
                                      (held->mesh.positions.capacity() + held->normals.capacity()) +
                                  sizeof(held->mesh.triangles[0]) * held->mesh.triangles.capacity());
      if (!held->hold) return refuse_for_responses(res);
      const auto parts = held->body.parts();
      set_held_content(res, {parts.begin(), parts.end()}, "application/octet-stream", held);
      log(req, run);
    } catch (const BadRequest& e) {
      answer_text(res, 400, e.what());
    } catch (const OptionError& e) {  // the engine's own checks of the options
      answer_text(res, 400, e.what());
    } catch (const InvalidInput& e) {
      answer_text(res, 400, e.what());
    } catch (const TriangleBudgetTooSmall& e) {  // no eps meets max-triangles
      answer_text(res, 400, e.what());
    } catch (const ExtractionCancelled&) {
      answer_text(res, 409, "superseded by a newer request of the same client");
    } catch (const std::bad_alloc&) {
      answer_text(res, 503, "out of memory for this extraction; try a larger eps");
    } catch (const std::exception& e) {  // IoError: a corrupt or unreadable brick, named
      answer_text(res, 500, e.what());
    }
  }

  void refuse_for_responses(httplib::Response& res) {
    res.set_header("Retry-After", "1");
    answer_text(res, 503,
                "busy: meshes not yet taken by their clients hold the server's budget for responses (" +
                    std::to_string(responses.budget() >> 20) + " MB); retry in a moment");
  }

  // Takes an extraction slot; false when too many wait already or the wait took too long. Throws
  // ExtractionCancelled when a newer request of the same client supersedes this one meanwhile.
  bool wait_for_slot(const Supersession::Ticket* ticket) {
    if (waiting.fetch_add(1) >= kWaitingExtractions) {
      waiting.fetch_sub(1);
      return false;
    }
    struct Leave {
      std::atomic<int>& n;
      ~Leave() { n.fetch_sub(1); }
    } leave{waiting};
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(kMaxWaitSeconds);
    while (!slots.try_acquire_for(std::chrono::milliseconds(20))) {
      if (ticket && ticket->superseded()) throw ExtractionCancelled{};
      if (std::chrono::steady_clock::now() > deadline) return false;
    }
    return true;
  }

  void log(const httplib::Request& req, const ExtractionRun& run) {
    if (!settings.log) return;
    const std::lock_guard<std::mutex> lock(log_mutex);
    std::fprintf(stderr, "isotope: %s iso %g eps %g %s: %lld triangles in %.1f ms\n", req.path.c_str(),
                 static_cast<double>(run.options.iso), run.options.eps,
                 std::string(to_string(run.options.topology)).c_str(), static_cast<long long>(run.topology.triangles),
                 1e3 * run.extract_seconds);
  }
};

ViewerServer::ViewerServer(const Settings& settings) : impl_(std::make_unique<Impl>(settings)) {}

ViewerServer::~ViewerServer() = default;

void ViewerServer::answer_connection(int socket) { impl_->http.serve_connection(socket); }

size_t ViewerServer::response_bytes_held() const { return impl_->responses.held(); }

int ViewerServer::bind(const std::string& host, int port) {
  const int bound = port == 0 ? impl_->http.bind_to_any_port(host) : (impl_->http.bind_to_port(host, port) ? port : -1);
  if (bound <= 0)
    throw IoError("cannot listen on " + host + ":" + std::to_string(port) +
                  " (in use, or not an address of this machine)");
  // cpp-httplib 0.11 listens with a backlog of 5: a crowd's connections beyond it were dropped by
  // the kernel and their clients timed out. listen() again on the bound socket sets the kernel's
  // largest backlog; the pool's workers then answer or refuse each (503) in turn.
  if (impl_->listen_socket >= 0) ::listen(impl_->listen_socket, SOMAXCONN);
  return bound;
}

bool ViewerServer::listen() {
  {
    const std::lock_guard<std::mutex> lock(impl_->run_mutex);
    if (impl_->stop_requested) return true;
    impl_->listening = true;
  }
  const bool ok = impl_->http.listen_after_bind();
  impl_->finished = true;
  return ok;
}

void ViewerServer::stop() {
  bool listening = false;
  {
    const std::lock_guard<std::mutex> lock(impl_->run_mutex);
    impl_->stop_requested = true;
    listening = impl_->listening;
  }
  // httplib's stop() does nothing until its accept loop runs, and a listen() just begun may not
  // be there yet: wait for the loop (or its end) first, else the listen would never return.
  if (!listening) return;
  while (!impl_->http.is_running() && !impl_->finished) std::this_thread::sleep_for(std::chrono::milliseconds(1));
  impl_->http.stop();
}

bool is_loopback_host(const std::string& host) {
  return host == "localhost" || host == "::1" || host.rfind("127.", 0) == 0;
}

}  // namespace isotope::tools
