// Colours a cloud triangulated by one camera with what a second camera saw
// (issue 7, "a second camera colours the cloud"): both cameras are
// calibrated against the same projector, so a point in the first camera's
// frame maps into the second's through the projector frame.
#pragma once

#include "sl/pipeline/camera_model.h"
#include "sl/pipeline/types.h"

namespace sl::pipeline {

// Replaces the intensity of every valid point of `cloud` (mm, frame of the
// camera calibrated by `own`) by the mean of `images`' frames (camera DN of
// the camera calibrated by `other`; for phase-shifting patterns the fringe
// offset A) at the point's projection, bilinear. Points behind that camera or
// projecting outside its image get a NaN intensity. There is no occlusion
// test: a point hidden from the other camera takes the colour of what hides
// it. Throws std::invalid_argument when `images` holds no frames or their
// size differs from `other`'s camera.
void transferIntensity(PointCloud& cloud, const CameraProjectorCalibration& own,
                       const CameraProjectorCalibration& other,
                       const CameraImages& images);

}  // namespace sl::pipeline
