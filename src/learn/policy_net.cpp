#include "learn/policy_net.h"

#include <torch/script.h>

#include <cmath>
#include <sstream>

#include "core/error.h"
#include "core/fs.h"

namespace twinforge::learn {

namespace {

// Appends Linear, LayerNorm and (with `relu`) ReLU.
void AddDense(torch::nn::Sequential& s, int in, int out, bool relu) {
  s->push_back(torch::nn::Linear(in, out));
  s->push_back(torch::nn::LayerNorm(torch::nn::LayerNormOptions({out})));
  if (relu) s->push_back(torch::nn::ReLU());
}

}  // namespace

PointEncoderImpl::PointEncoderImpl(int features) {
  torch::nn::Sequential per_point, project;
  AddDense(per_point, features, 64, true);
  AddDense(per_point, 64, 128, true);
  AddDense(per_point, 128, 256, false);
  AddDense(project, 256, kOut, false);
  per_point_ = register_module("per_point", per_point);
  project_ = register_module("project", project);
}

torch::Tensor PointEncoderImpl::forward(const torch::Tensor& points) {
  return project_->forward(std::get<0>(per_point_->forward(points).max(1)));
}

PolicyNetImpl::PolicyNetImpl(const PolicyConfig& config) : config_(config) {
  int in = config.proprio_dim;
  if (config.point_features > 0) {
    encoder_ = register_module("encoder", PointEncoder(config.point_features));
    in += PointEncoderImpl::kOut;
  }
  torch::nn::Linear out(config.hidden, config.action_dim);
  head_ = register_module(
      "head", torch::nn::Sequential(torch::nn::Linear(in, config.hidden), torch::nn::Tanh(),
                                    torch::nn::Linear(config.hidden, config.hidden),
                                    torch::nn::Tanh(), out));
  // A small last layer: the first actions are near uniform (discrete) or near zero.
  torch::NoGradGuard no_grad;
  out->weight.mul_(0.01);
  out->bias.zero_();
  if (!config.discrete) {
    action_scale_ = config.action_scale.empty()
                        ? torch::ones({config.action_dim})
                        : torch::tensor(std::vector<float>(config.action_scale.begin(),
                                                           config.action_scale.end()));
    log_std = register_parameter("log_std", (0.5 * action_scale_).log());
  }
  obs_mean = register_buffer("obs_mean", torch::zeros({config.proprio_dim}));
  obs_std = register_buffer("obs_std", torch::ones({config.proprio_dim}));
}

torch::Tensor PolicyNetImpl::Normalize(const torch::Tensor& proprio) const {
  return ((proprio - obs_mean) / obs_std).clamp(-kObsClip, kObsClip);
}

torch::Tensor PolicyNetImpl::Features(const torch::Tensor& points,
                                      const torch::Tensor& normalized) {
  return encoder_ ? torch::cat({encoder_->forward(points), normalized}, 1) : normalized;
}

torch::Tensor PolicyNetImpl::ForwardNormalized(const torch::Tensor& points,
                                               const torch::Tensor& normalized) {
  return Head(Features(points, normalized));
}

torch::Tensor PolicyNetImpl::HeadInput(const torch::Tensor& points, const torch::Tensor& proprio) {
  return Features(points, Normalize(proprio));
}

torch::Tensor PolicyNetImpl::Head(const torch::Tensor& head_input) {
  const torch::Tensor out = head_->forward(head_input);
  return config_.discrete ? out : out * action_scale_;
}

int PolicyNetImpl::HeadInputDim() const {
  return config_.proprio_dim + (encoder_ ? PointEncoderImpl::kOut : 0);
}

torch::Tensor PolicyNetImpl::forward(const torch::Tensor& points, const torch::Tensor& proprio) {
  return ForwardNormalized(points, Normalize(proprio));
}

torch::Tensor PolicyNetImpl::LogProb(const torch::Tensor& output,
                                     const torch::Tensor& actions) const {
  if (config_.discrete)
    return torch::log_softmax(output, 1).gather(1, actions.to(torch::kLong).view({-1, 1})).view(-1);
  const torch::Tensor z = (actions - output) / log_std.exp();
  return (-0.5 * z * z - log_std - 0.5 * std::log(2 * M_PI)).sum(1);
}

void SavePolicy(PolicyNet& net, const std::filesystem::path& path) {
  torch::serialize::OutputArchive archive;
  net->save(archive);
  archive.write("twinforge_policy_config", c10::IValue(core::ToJson(net->config()).dump()));
  const auto tmp = path.string() + ".tmp";
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  archive.save_to(tmp);
  std::filesystem::rename(tmp, path);
}

PolicyNet LoadPolicy(const std::filesystem::path& path) {
  if (!std::filesystem::is_regular_file(path))
    throw core::IoError("no policy file at " + path.string());
  torch::serialize::InputArchive archive;
  c10::IValue config_text;
  try {
    archive.load_from(path.string());
    if (!archive.try_read("twinforge_policy_config", config_text))
      throw core::Error(path.string() + ": a LibTorch archive, but not a twinforge policy");
  } catch (const c10::Error& e) {
    throw core::Error(path.string() + ": not a policy file (" + e.what_without_backtrace() + ")");
  }
  const auto config = core::ReadConfig<PolicyConfig>(
      core::ParseConfigText(config_text.toStringRef(), path.string() + " (config)"));
  PolicyNet net(config);
  try {
    net->load(archive);
  } catch (const c10::Error& e) {
    throw core::Error(path.string() + ": weights do not match the network its config describes (" +
                      e.what_without_backtrace() + ")");
  }
  return net;
}

void ExportTorchScript(PolicyNet& net, const std::filesystem::path& path) {
  torch::NoGradGuard no_grad;
  const PolicyConfig& config = net->config();
  torch::jit::Module module("TwinforgePolicy");
  // Every tensor becomes an attribute named by its path with '_' for '.', e.g. head_0_weight.
  const auto name = [](std::string n) {
    for (char& c : n)
      if (c == '.') c = '_';
    return n;
  };
  for (const auto& p : net->named_parameters())
    module.register_parameter(name(p.key()), p.value().clone(), false);
  for (const auto& b : net->named_buffers())
    module.register_buffer(name(b.key()), b.value().clone());
  if (!config.discrete) module.register_buffer("action_scale", net->ActionScale().clone());
  // The code mirrors PointEncoderImpl and PolicyNetImpl layer by layer.
  std::ostringstream code;
  const auto linear = [&](const std::string& in, const std::string& layer) {
    return "torch.linear(" + in + ", self." + layer + "_weight, self." + layer + "_bias)";
  };
  const auto norm = [&](const std::string& in, const std::string& layer, int width) {
    return "torch.layer_norm(" + in + ", [" + std::to_string(width) + "], self." + layer +
           "_weight, self." + layer + "_bias, 1e-05)";
  };
  code << "def forward(self, points: Tensor, proprio: Tensor) -> Tensor:\n"
       << "    x = torch.clamp((proprio - self.obs_mean) / self.obs_std, -"
       << PolicyNetImpl::kObsClip << ", " << PolicyNetImpl::kObsClip << ")\n";
  if (config.point_features > 0) {
    const std::string e = "encoder_per_point_";
    code << "    p = torch.relu(" << norm(linear("points", e + "0"), e + "1", 64) << ")\n"
         << "    p = torch.relu(" << norm(linear("p", e + "3"), e + "4", 128) << ")\n"
         << "    p = " << norm(linear("p", e + "6"), e + "7", 256) << "\n"
         << "    p = torch.amax(p, 1)\n"
         << "    p = "
         << norm(linear("p", "encoder_project_0"), "encoder_project_1", PointEncoderImpl::kOut)
         << "\n"
         << "    x = torch.cat([p, x], 1)\n";
  }
  code << "    x = torch.tanh(" << linear("x", "head_0") << ")\n"
       << "    x = torch.tanh(" << linear("x", "head_2") << ")\n"
       << "    return " << linear("x", "head_4") << (config.discrete ? "" : " * self.action_scale")
       << "\n";
  module.define(code.str());
  const auto tmp = path.string() + ".tmp";
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  module.save(tmp);
  std::filesystem::rename(tmp, path);
}

int64_t ParameterCount(torch::nn::Module& module) {
  int64_t n = 0;
  for (const auto& p : module.parameters()) n += p.numel();
  return n;
}

}  // namespace twinforge::learn
