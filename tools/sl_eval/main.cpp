// sl_eval EXPERIMENT [--scans N] [--out DIR]: runs one of the paper's
// experiments on the simulated sensor and prints a Markdown table; plots go
// to DIR (default sl_eval_out). Exit codes: 0 ok, 1 error, 2 usage.
#include <cstdlib>
#include <iostream>
#include <string>

#include "eval.h"

namespace {

int usage() {
  std::cerr << "usage: sl_eval EXPERIMENT [--scans N] [--out DIR]\n  experiments:";
  for (const std::string& n : sl::eval::experimentNames()) std::cerr << ' ' << n;
  std::cerr << "\n";
  return 2;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) return usage();
  const std::string experiment = argv[1];
  if (experiment == "-h" || experiment == "--help") return usage(), 0;
  sl::eval::EvalOptions options;
  options.out_dir = "sl_eval_out";
  for (int i = 2; i < argc; ++i) {
    const std::string arg = argv[i];
    if ((arg == "--scans" || arg == "--out") && i + 1 < argc) {
      const std::string value = argv[++i];
      if (arg == "--out") {
        options.out_dir = value;
      } else {
        try {
          options.scans = std::stoi(value);
        } catch (const std::exception&) {
          return usage();
        }
      }
    } else {
      return usage();
    }
  }
  try {
    const sl::eval::EvalResult result = sl::eval::runExperiment(experiment, options);
    std::cout << result.markdown;
    for (const std::string& plot : result.plots) std::cout << "\nplot: " << plot << "\n";
    return 0;
  } catch (const std::invalid_argument& e) {
    std::cerr << "sl_eval: " << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "sl_eval: " << e.what() << "\n";
    return 1;
  }
}
