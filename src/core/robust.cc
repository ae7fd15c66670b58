#include "insitu/core/robust.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>

namespace insitu {
namespace {

template <typename T>
double MedianOf(std::span<T> values) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  const auto mid = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), mid, values.end());
  return *mid;
}

template <typename T>
double AbsDeviationFrom(std::vector<T>& values, T centre) {
  for (T& v : values) v = std::abs(v - centre);
  return MedianOf(std::span<T>(values));
}

}  // namespace

double MedianInPlace(std::span<double> values) { return MedianOf(values); }
double MedianInPlace(std::span<float> values) { return MedianOf(values); }

double MedianAbsDeviationFrom(std::vector<double> values, double centre) {
  return AbsDeviationFrom(values, centre);
}
double MedianAbsDeviationFrom(std::vector<float> values, float centre) {
  return AbsDeviationFrom(values, centre);
}

double MedianAbsDeviation(std::vector<double> values) {
  const double median = MedianInPlace(values);
  return AbsDeviationFrom(values, median);
}
double MedianAbsDeviation(std::vector<float> values) {
  // The median of floats is one of them: the narrowing is exact.
  const float median = static_cast<float>(MedianInPlace(values));
  return AbsDeviationFrom(values, median);
}

}  // namespace insitu
