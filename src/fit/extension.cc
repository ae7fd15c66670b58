#include "insitu/fit/extension.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <sstream>

#include "insitu/core/config.h"
#include "insitu/core/file.h"

namespace insitu::fit {

Result<ModelExtension> ModelExtension::Make(const std::vector<EffectParams>& effects) {
  ModelExtension ext;
  for (const EffectParams& e : effects) {
    std::shared_ptr<const Effect> impl = MakeEffect(e.name);
    if (!impl) return InvalidArgument("unknown effect '" + e.name + "'");
    const size_t want = impl->param_names().size();
    if (e.params.size() != want) {
      return InvalidArgument("effect '" + e.name + "' takes " + std::to_string(want) +
                             " parameters, got " + std::to_string(e.params.size()));
    }
    for (double v : e.params) {
      if (!std::isfinite(v))
        return InvalidArgument("effect '" + e.name + "': a parameter is not finite");
    }
    ext.effects_.push_back(e);
    ext.impl_.push_back(std::move(impl));
  }
  return ext;
}

Result<ModelExtension> ModelExtension::FromDiagnosis(const Diagnosis& d) {
  std::vector<EffectParams> effects;
  for (const EffectReport& e : d.effects) effects.push_back({e.name, e.params});
  return Make(effects);
}

Eigen::Vector2d ModelExtension::Forward(const FieldPoint& p) const {
  Eigen::Vector2d uv = p.cmd;
  for (int stage = 0; stage <= 2; ++stage) {
    for (size_t k = 0; k < impl_.size(); ++k) {
      if (impl_[k]->stage() == stage) impl_[k]->Apply(p, effects_[k].params.data(), &uv);
    }
  }
  return uv;
}

Eigen::Vector2d ModelExtension::Forward(const Eigen::Vector2d& cmd, double z) const {
  FieldPoint p;
  p.cmd = cmd;
  p.z_cmd_mm = z;
  return Forward(p);
}

Eigen::Vector2d ModelExtension::Inverse(const Eigen::Vector2d& target, double z) const {
  Eigen::Vector2d cmd = target;
  for (int it = 0; it < 20; ++it) {
    const Eigen::Vector2d miss = target - Forward(cmd, z);
    cmd += miss;
    if (miss.norm() < 1e-9) break;
  }
  return cmd;
}

Status SaveExtension(const ModelExtension& ext, const std::string& origin,
                     const std::string& path) {
  std::ostringstream f;
  f << "# A model extension from insitu diagnose: library effects with fitted parameters.\n"
    << "version: 1\nproduced_by: insitu diagnose\ndata: \"" << origin << "\"\neffects:";
  if (ext.empty()) f << " []";
  f << "\n";
  for (const EffectParams& e : ext.effects()) {
    const auto names = MakeEffect(e.name)->param_names();
    f << "  - name: " << e.name << "\n    params: [";
    for (size_t k = 0; k < e.params.size(); ++k) {
      char buf[40];
      std::snprintf(buf, sizeof buf, "%.10g", e.params[k]);
      f << (k ? ", " : "") << buf;
    }
    f << "]   #";
    for (const auto& n : names) f << " " << n;
    f << "\n";
  }
  return WriteFileAtomically(path, f.str());
}

Result<ModelExtension> LoadExtension(const std::string& path) {
  INSITU_ASSIGN_OR_RETURN(ConfigNode root, ConfigNode::LoadFile(path));
  ConfigReader r(root);
  int version = 0;
  std::string text;
  r.Require("version");
  r.Read("version", &version);
  r.Read("produced_by", &text);
  r.Read("data", &text);
  r.Skip("effects");
  if (r.ok() && version != 1) r.Fail("version", "this insitu reads extension files of version 1");
  INSITU_RETURN_IF_ERROR(r.Finish());
  const ConfigNode list = root.Child("effects");
  std::vector<EffectParams> effects;
  if (list.IsDefined() && !list.IsNull()) {
    if (!list.IsSequence()) return ParseError(list.Where() + ": effects must be a list");
    for (size_t i = 0; i < list.size(); ++i) {
      ConfigReader e(list.At(i));
      EffectParams p;
      e.Require("name");
      e.Require("params");
      e.Read("name", &p.name);
      e.Read("params", &p.params);
      INSITU_RETURN_IF_ERROR(e.Finish());
      effects.push_back(p);
    }
  }
  auto ext = ModelExtension::Make(effects);
  if (!ext.ok()) return ext.status().Prefixed(path);
  return ext;
}

}  // namespace insitu::fit
