// isotope_bench_api: the C++ path that the Python module's calls take (isotope._isotope), timed
// in process, so that the Python overhead benchmark (bench/README.md) can set the Python path beside
// it in the same run:
//   BM_ApiExtract/array/eps:E   open_volume(Volume borrowing a float array) + Source::extract:
//                               isotope.extract(float32_array, iso, eps=E)
//   BM_ApiExtract/file/eps:E    open_volume(raw file) + Source::extract: isotope.extract(path, ...)
// Usage: isotope_bench_api --volume NAME_XxYxZ_TYPE.raw --iso V --eps 0,16 [benchmark flags]
#include <benchmark/benchmark.h>

#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <span>
#include <sstream>
#include <string>
#include <vector>

#include "io/volume/volume_reader.h"  // read_volume: the file's values as the array Python is handed
#include <isotope/isotope.h>

namespace {

struct Args {
  std::string volume;
  float iso = 0;
  std::vector<double> eps;
};

isotope::ExtractOptions options_for(const Args& a, double eps) {
  isotope::ExtractOptions o;
  o.iso = a.iso;
  o.eps = eps;
  return o;
}

void BM_ApiExtractArray(benchmark::State& state, const isotope::Volume* values, isotope::ExtractOptions o) {
  int64_t triangles = 0;
  for (auto _ : state) {
    isotope::Volume v;
    v.dims = values->dims;
    v.borrowed = std::span<const float>(values->values);
    const isotope::Source source = isotope::open_volume(std::move(v));
    const isotope::Mesh mesh = source.extract(o);
    triangles = static_cast<int64_t>(mesh.triangles.size());
    benchmark::DoNotOptimize(mesh.triangles.data());
  }
  state.counters["triangles"] = static_cast<double>(triangles);
}

void BM_ApiExtractFile(benchmark::State& state, std::string path, isotope::ExtractOptions o) {
  int64_t triangles = 0;
  for (auto _ : state) {
    const isotope::Source source = isotope::open_volume(isotope::VolumeSpec{path, std::nullopt, std::nullopt});
    const isotope::Mesh mesh = source.extract(o);
    triangles = static_cast<int64_t>(mesh.triangles.size());
    benchmark::DoNotOptimize(mesh.triangles.data());
  }
  state.counters["triangles"] = static_cast<double>(triangles);
}

// Our flags are taken out of argv before Google Benchmark reads the rest.
Args take_args(int& argc, char** argv) {
  Args a;
  int kept = 1;
  for (int i = 1; i < argc; ++i) {
    const std::string flag = argv[i];
    if ((flag == "--volume" || flag == "--iso" || flag == "--eps") && i + 1 < argc) {
      const std::string value = argv[++i];
      if (flag == "--volume") a.volume = value;
      if (flag == "--iso") a.iso = std::stof(value);
      if (flag == "--eps") {
        std::stringstream list(value);
        for (std::string e; std::getline(list, e, ',');) a.eps.push_back(std::stod(e));
      }
    } else {
      argv[kept++] = argv[i];
    }
  }
  argc = kept;
  if (a.volume.empty() || a.eps.empty()) {
    std::fprintf(stderr,
                 "usage: isotope_bench_api --volume NAME_XxYxZ_TYPE.raw --iso V --eps E[,E...] [--benchmark_...]\n");
    std::exit(2);
  }
  return a;
}

}  // namespace

int main(int argc, char** argv) {
  const Args a = take_args(argc, argv);
  // The array the Python path is handed: the file's values as float32, read once, outside the timing.
  static const isotope::Volume values = isotope::read_volume(isotope::VolumeSpec{a.volume, std::nullopt, std::nullopt});
  benchmark::Initialize(&argc, argv);
  for (const double eps : a.eps) {
    char name[64];
    std::snprintf(name, sizeof name, "eps:%g", eps);
    benchmark::RegisterBenchmark((std::string("BM_ApiExtract/array/") + name).c_str(), BM_ApiExtractArray, &values,
                                 options_for(a, eps))
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
    benchmark::RegisterBenchmark((std::string("BM_ApiExtract/file/") + name).c_str(), BM_ApiExtractFile, a.volume,
                                 options_for(a, eps))
        ->Unit(benchmark::kMillisecond)
        ->UseRealTime();
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
