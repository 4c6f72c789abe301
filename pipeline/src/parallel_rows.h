// Row loops spread over OpenCV's thread pool (private).
//
// ThreadSanitizer builds (SL_SANITIZE=thread) run the rows on the calling
// thread instead: OpenCV's parallel_for_ backend here is TBB, which is not
// instrumented, so TSan does not see TBB hand a loop's rows to its worker
// threads and back, and reports each body as racing with its caller (the
// std::function on the caller's stack, the rows written, the caller reading
// them afterwards). The bodies write disjoint rows; the pipeline's own
// threads (RowWorkers) stay checked.
#pragma once

#include <opencv2/core.hpp>

namespace sl::pipeline {

// Calls body(cv::Range) over [0, rows), possibly in parallel stripes.
template <typename Body>
void parallelRows(int rows, const Body& body) {
#if defined(__SANITIZE_THREAD__)
  body(cv::Range(0, rows));
#else
  cv::parallel_for_(cv::Range(0, rows), body);
#endif
}

}  // namespace sl::pipeline
