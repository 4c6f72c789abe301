// sl_eval EXPERIMENT|all [--scans N] [--out DIR] [--gamma G] [--save-scans DIR |
// --load-scans DIR]: runs the paper's
// experiments on the simulated sensor and prints Markdown tables; plots go to
// DIR (default sl_eval_out). `all` runs every experiment in turn with its
// default scan count (or N) and reports progress on stderr.
// Exit codes: 0 ok, 1 error, 2 usage.
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <iostream>
#include <string>
#include <vector>

#include "eval.h"

namespace {

int usage() {
  std::cerr << "usage: sl_eval EXPERIMENT|all [--scans N] [--out DIR] [--gamma G]\n"
               "               [--save-scans DIR | --load-scans DIR]\n  experiments:";
  for (const std::string& n : sl::eval::experimentNames()) std::cerr << ' ' << n;
  std::cerr << "\n  --scans N: scans per condition (default: each experiment's own)"
               "\n  --gamma G: simulated projector response (level / 255)^G (default 1, linear;"
               "\n             for `gamma`: the non-linear case, default 2.2)"
               "\n  --save-scans DIR: wall: write the scans (PLY), true poses and prior (TUM) there"
               "\n  --load-scans DIR: wall: register and evaluate scans so written (no scanning)\n";
  return 2;
}

void print(const sl::eval::EvalResult& result) {
  std::cout << result.markdown;
  for (const std::string& plot : result.plots) std::cout << "\nplot: " << plot << "\n";
  std::cout << std::flush;
}

int runAll(const sl::eval::EvalOptions& options) {
  using Clock = std::chrono::steady_clock;
  const auto start = Clock::now();
  auto seconds = [](Clock::duration d) { return std::chrono::duration<double>(d).count(); };
  const std::vector<std::string> names = sl::eval::experimentNames();
  for (std::size_t i = 0; i < names.size(); ++i) {
    const auto begin = Clock::now();
    std::fprintf(stderr, "sl_eval: [%zu/%zu] %s ... (elapsed %.0f s)\n", i + 1, names.size(),
                 names[i].c_str(), seconds(begin - start));
    const sl::eval::EvalResult result = sl::eval::runExperiment(names[i], options);
    std::fprintf(stderr, "sl_eval: [%zu/%zu] %s done in %.1f s\n", i + 1, names.size(),
                 names[i].c_str(), seconds(Clock::now() - begin));
    if (i > 0) std::cout << "\n";
    print(result);
  }
  std::fprintf(stderr, "sl_eval: all %zu experiments done in %.1f s\n", names.size(),
               seconds(Clock::now() - start));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage();
  const std::string experiment = argv[1];
  if (experiment == "-h" || experiment == "--help") return usage(), 0;
  if (experiment.empty() || experiment[0] == '-') {
    std::cerr << "sl_eval: " << (experiment.empty() ? "no experiment" : "unknown option " + experiment)
              << "\n";
    return usage();
  }
  sl::eval::EvalOptions options;
  options.out_dir = "sl_eval_out";
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    if ((arg == "--scans" || arg == "--out" || arg == "--gamma" || arg == "--save-scans" ||
         arg == "--load-scans") &&
        i + 1 < argc) {
      const std::string value = argv[++i];
      if (arg == "--out") {
        options.out_dir = value;
      } else if (arg == "--save-scans") {
        options.save_scans_dir = value;
      } else if (arg == "--load-scans") {
        options.load_scans_dir = value;
      } else if (arg == "--gamma") {
        try {
          std::size_t used = 0;
          options.projector_gamma = std::stod(value, &used);
          if (used != value.size() || !(options.projector_gamma > 0)) return usage();
        } catch (const std::exception&) {
          return usage();
        }
      } else {
        try {
          std::size_t used = 0;
          options.scans = std::stoi(value, &used);
          if (used != value.size() || options.scans < 1) return usage();
        } catch (const std::exception&) {
          return usage();
        }
      }
    } else {
      return usage();
    }
  }
  try {
    if (experiment == "all") return runAll(options);
    print(sl::eval::runExperiment(experiment, options));
    return 0;
  } catch (const std::invalid_argument& e) {
    std::cerr << "sl_eval: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "sl_eval: " << e.what() << "\n";
    return 1;
  }
}
