// Robust location and spread of a sample: its median and its median absolute deviation.
//
// The median is the element of rank n / 2 (0-based) once the sample is sorted: for an even
// count the upper of the two middle values, not their mean. Every robust threshold in insitu
// (outlier cuts at k robust sigmas, background levels, pitches) was tuned with it. An empty
// sample's median is NaN. A sample holding NaN has no order: drop the NaNs first.
//
// A Gaussian's sigma is kMadToSigma times its median absolute deviation.
#pragma once

#include <span>
#include <vector>

namespace insitu {

// sigma = kMadToSigma * MAD for normally distributed values (1 / Phi^-1(3/4)).
inline constexpr double kMadToSigma = 1.4826;

// The median of `values`, reordering them (no copy): what a hot loop or a scratch buffer uses.
double MedianInPlace(std::span<double> values);
double MedianInPlace(std::span<float> values);

// The median of `values` (a copy is reordered).
inline double Median(std::vector<double> values) { return MedianInPlace(values); }
inline double Median(std::vector<float> values) { return MedianInPlace(values); }

// Median of |v - centre|: the spread of values about a known centre (0 for residuals).
// NaN when empty. Float samples take |v - centre| in float, as their median is a float.
double MedianAbsDeviationFrom(std::vector<double> values, double centre);
double MedianAbsDeviationFrom(std::vector<float> values, float centre);

// Median of |v - Median(v)|, the sample's spread about its own median; NaN when empty.
double MedianAbsDeviation(std::vector<double> values);
double MedianAbsDeviation(std::vector<float> values);

}  // namespace insitu
