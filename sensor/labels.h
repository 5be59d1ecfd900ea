// Detectability labels of the ground truth's objects under one acquisition (labels.exr). They depend on
// the sensor and the gate sweep, so they are computed with the sensor's rates, by spadgen run and again
// by spadgen sense for its own settings, from the same ground-truth values (docs/outputs.md, "labels.exr").
//
// Object o of a pixel returns object<j>.laser photons per pulse directly; modelled as a delta at
// t_o = emission_delay + 2 range_o / c, it adds lambda_o(k) avalanches per frame at gate position k
// (SensorModel::return_lambda, with the crosstalk the same light fires through the neighbours). lambda(k)
// is the pixel's full noise-free rate (detection_rate.npy). At k*, the first k with lambda_o(k) >= 0.95
// max_k lambda_o(k) (just past the object's rising edge; when that is k = 0, the sweep beginning on the
// object's plateau, the last such k, just before its falling edge, and no edge when that is K - 1), the
// object turns the expected counts of N frames from N p0 to N p1, p1 = 1 - exp(-lambda(k*)),
// p0 = 1 - exp(-(lambda(k*) - lambda_o(k*))) (the difference taken as 0 within what lambda_o is known to:
// n xt of it, and lambda's float rounding):
//   edge_counts = N (exp(-(lambda(k*) - lambda_o(k*))) - exp(-lambda(k*))) = N (p1 - p0)
//   edge_snr    = edge_counts / sqrt(N p1 (1 - p1) / n1 + N p0 (1 - p0) / n0)   (infinite where the
//                 noise is 0 and the edge is not, 0 where both are)
// the step over the standard deviation of the difference of the mean counts of the gate positions on
// either side of the edge, kEdgeGates of them or as many as the sweep holds: n1 along the object's plateau
// from k*, n0 on the other side to the sweep's end; detectable = edge_snr >= kDetectableSnr. An object
// without light in the sweep has edge 0.
#pragma once
#include "core/tile.h"
#include "core/time_axis.h"
#include "sensor/sensor.h"

namespace spadgen::sensor {

// The step of the noise-free profile at five standard deviations of the difference of two means of 12
// gate positions each (432 ps at the paper's 36 ps step, well inside the 3.8 ns plateau): an edge that a
// detector averaging the counts either side of it, as the reference detectors do (docs/detection.md: the
// paper's 6-position plateaus of a 5-position moving average; scales up to 24), would not mistake for
// noise. One gate position alone would call the paper's sphere behind its plate invisible, which both
// detectors find.
constexpr double kDetectableSnr = 5.0;
constexpr double kEdgeGates = 12.0;
// k*: the first gate position where the object's own rate reaches this fraction of its maximum.
constexpr double kEdgeFraction = 0.95;

// Labels of gt's object slots from the sensor tile of the same pixels (s.rate must be kept: the rates of
// every k), on the time axis the light was rendered on. emission_delay_s: laser.emission_delay.
ObjectLabelsTile object_labels(const SensorModel& sensor, const GroundTruthTile& gt, const SensorTile& s,
                               const TimeAxis& axis, double emission_delay_s);

}  // namespace spadgen::sensor
