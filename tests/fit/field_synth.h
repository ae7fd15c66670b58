// Generated galvo field data for the fit tests: a square grid of commanded points, the spot
// moved by library effects with given parameters, plus seeded Gaussian measurement noise.
#pragma once

#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "insitu/fit/effects.h"
#include "insitu/fit/field_data.h"

namespace insitu::fit::testing {

struct Synth {
  int grid = 11;            // grid x grid commanded points
  double half_mm = 50.0;    // field +-half_mm
  double noise_mm = 0.002;  // per axis, Gaussian
  int replicates = 1;       // measurements per commanded point
  uint64_t seed = 1;
  std::vector<std::pair<std::string, std::vector<double>>> effects;  // library name, params
  // An extra displacement outside the library (for the off-library case).
  std::function<Eigen::Vector2d(const Eigen::Vector2d&)> extra;
};

inline FieldData Generate(const Synth& s) {
  FieldData d;
  d.origin = "<generated>";
  std::mt19937_64 rng(s.seed);
  std::normal_distribution<double> gauss(0.0, 1.0);
  std::vector<std::unique_ptr<Effect>> effects;
  for (const auto& [name, params] : s.effects) effects.push_back(MakeEffect(name));
  for (int j = 0; j < s.grid; ++j) {
    for (int i = 0; i < s.grid; ++i) {
      const Eigen::Vector2d cmd(-s.half_mm + 2.0 * s.half_mm * i / (s.grid - 1),
                                -s.half_mm + 2.0 * s.half_mm * j / (s.grid - 1));
      for (int r = 0; r < s.replicates; ++r) {
        FieldPoint p;
        p.cmd = cmd;
        Eigen::Vector2d uv = cmd;
        // Stages in order, as a model applies them.
        for (int stage = 0; stage <= 2; ++stage) {
          for (size_t k = 0; k < effects.size(); ++k) {
            if (effects[k]->stage() == stage) effects[k]->Apply(p, s.effects[k].second.data(), &uv);
          }
        }
        if (s.extra) uv += s.extra(cmd);
        p.meas = uv + s.noise_mm * Eigen::Vector2d(gauss(rng), gauss(rng));
        d.points.push_back(p);
      }
    }
  }
  return d;
}

}  // namespace insitu::fit::testing
