// The projector interface implemented by the simulated and LightCrafter 4500
// projectors.
#pragma once

#include <stdexcept>
#include <string>
#include <vector>

namespace sl::drivers {

// A pattern sequence the projector can run, as stored in the device (flash
// images / LUT entries) or rendered by the simulator.
struct ProjectorSequence {
  std::string name;          // pattern name, e.g. "3+3_horizontal"
  int frame_count = 0;       // patterns per sequence
};

// Implementations must be thread-safe: the engine calls select/start/stop
// from the thread serving requests and from its control thread (switches,
// software trigger: projectSingle), and stop from its destructor
// (LightCrafter4500Projector and the simulated projector take a mutex).
class Projector {
 public:
  virtual ~Projector() = default;
  virtual std::string id() const = 0;
  virtual std::vector<ProjectorSequence> sequences() const = 0;
  // Selects the sequence to run next; throws std::invalid_argument on an
  // unknown name. Not allowed while running.
  virtual void select(const std::string& name) = 0;
  // Starts projecting the selected sequence `count` times (0 = until stop()).
  virtual void start(int count) = 0;
  virtual void stop() = 0;  // also ends projectSingle()

  // Software triggering: shows pattern `index` (0-based) of the selected
  // sequence and holds it until the next call or stop(); not while running.
  // Projectors that cannot say false and throw std::logic_error.
  virtual bool canProjectSingle() const { return false; }
  virtual void projectSingle(int index) {
    throw std::logic_error("projector '" + id() + "' cannot show single patterns (" +
                           std::to_string(index) + ")");
  }
};

}  // namespace sl::drivers
