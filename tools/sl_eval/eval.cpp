// sl_eval's experiments by name (eval.h); each experiment is in its own
// file: precision.cpp, motion.cpp, cones.cpp, roughness.cpp, vdi2634.cpp,
// gamma.cpp, wall.cpp, adaptive.cpp; their shared setup in common.h.
#include "eval.h"

#include <stdexcept>
#include <string>
#include <vector>

namespace sl::eval {

std::vector<std::string> experimentNames() {
  return {"precision", "cones", "roughness", "motion", "vdi2634", "gamma", "wall", "adaptive"};
}

int defaultScans(const std::string& name) {
  if (name == "vdi2634") return 1;  // the guideline measures each pose once
  if (name == "wall") return 21;    // horizontal pass: 25 mm apart
  if (name == "adaptive") return 20;  // two stop-go cycles
  return 10;                        // the paper's 10 consecutive scans
}

EvalResult runExperiment(const std::string& name, const EvalOptions& options) {
  if (name == "precision") return runPrecision(options);
  if (name == "motion") return runMotion(options);
  if (name == "cones") return runCones(options);
  if (name == "roughness") return runRoughness(options);
  if (name == "vdi2634") return runVdi2634(options);
  if (name == "gamma") return runGamma(options);
  if (name == "wall") return runWall(options);
  if (name == "adaptive") return runAdaptive(options);
  std::string known;
  for (const std::string& n : experimentNames()) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown experiment '" + name + "' (known: " + known + ")");
}

}  // namespace sl::eval
