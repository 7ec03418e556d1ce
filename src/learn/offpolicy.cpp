#include "learn/offpolicy.h"

#include <cmath>

#include "core/error.h"

namespace twinforge::learn {

namespace {

torch::nn::Sequential Mlp(int in, int hidden, int out, bool zero_last) {
  torch::nn::Linear last(hidden, out);
  if (zero_last) {
    torch::NoGradGuard no_grad;
    last->weight.zero_();
    last->bias.zero_();
  }
  return torch::nn::Sequential(torch::nn::Linear(in, hidden), torch::nn::ReLU(),
                               torch::nn::Linear(hidden, hidden), torch::nn::ReLU(), last);
}

torch::nn::Sequential Copy(const torch::nn::Sequential& net) {
  auto copy = std::dynamic_pointer_cast<torch::nn::SequentialImpl>(net->clone());
  for (auto& p : copy->parameters()) p.set_requires_grad(false);
  return torch::nn::Sequential(copy);
}

// target <- (1 - tau) target + tau source.
void Polyak(torch::nn::Sequential& target, const torch::nn::Sequential& source, double tau) {
  torch::NoGradGuard no_grad;
  auto t = target->parameters();
  const auto s = source->parameters();
  for (std::size_t i = 0; i < t.size(); ++i) t[i].mul_(1 - tau).add_(s[i], tau);
}

void CheckFinite(const float* v, int n, const char* field) {
  for (int i = 0; i < n; ++i)
    if (!std::isfinite(v[i]))
      throw core::NumericError(std::string("replay buffer: ") + field + "[" + std::to_string(i) +
                               "] is " + std::to_string(v[i]));
}

torch::Tensor Rows(const std::vector<float>& data, const std::vector<int64_t>& rows, int width) {
  torch::Tensor out = torch::empty({int64_t(rows.size()), width});
  float* o = out.data_ptr<float>();
  for (std::size_t r = 0; r < rows.size(); ++r)
    std::copy_n(data.data() + rows[r] * width, width, o + r * width);
  return out;
}

torch::Tensor FromRow(const float* v, int n) {
  return torch::from_blob(const_cast<float*>(v), {1, n}).clone();
}

}  // namespace

ReplayBuffer::ReplayBuffer(int obs_dim, int action_dim, int64_t capacity)
    : obs_dim_(obs_dim), action_dim_(action_dim), capacity_(capacity) {
  if (obs_dim <= 0 || action_dim <= 0 || capacity <= 0)
    throw core::Error("replay buffer: sizes must be positive (obs " + std::to_string(obs_dim) +
                      ", action " + std::to_string(action_dim) + ", capacity " +
                      std::to_string(capacity) + ")");
  obs_.resize(capacity * obs_dim);
  next_obs_.resize(capacity * obs_dim);
  base_.resize(capacity * action_dim);
  next_base_.resize(capacity * action_dim);
  action_.resize(capacity * action_dim);
  reward_.resize(capacity);
  terminal_.resize(capacity);
}

void ReplayBuffer::Add(const float* obs, const float* base, const float* action, float reward,
                       const float* next_obs, const float* next_base, bool terminal) {
  CheckFinite(obs, obs_dim_, "obs");
  CheckFinite(next_obs, obs_dim_, "next_obs");
  CheckFinite(action, action_dim_, "action");
  CheckFinite(&reward, 1, "reward");
  if (base) CheckFinite(base, action_dim_, "base");
  if (next_base) CheckFinite(next_base, action_dim_, "next_base");
  const int64_t i = next_;
  std::copy_n(obs, obs_dim_, obs_.data() + i * obs_dim_);
  std::copy_n(next_obs, obs_dim_, next_obs_.data() + i * obs_dim_);
  std::copy_n(action, action_dim_, action_.data() + i * action_dim_);
  float* b = base_.data() + i * action_dim_;
  float* nb = next_base_.data() + i * action_dim_;
  if (base)
    std::copy_n(base, action_dim_, b);
  else
    std::fill_n(b, action_dim_, 0.0f);
  if (next_base)
    std::copy_n(next_base, action_dim_, nb);
  else
    std::fill_n(nb, action_dim_, 0.0f);
  reward_[i] = reward;
  terminal_[i] = terminal ? 1.0f : 0.0f;
  next_ = (next_ + 1) % capacity_;
  size_ = std::min(size_ + 1, capacity_);
}

ReplayBuffer::Batch ReplayBuffer::Sample(int n, core::Rng& rng) const {
  if (size_ == 0) throw core::Error("replay buffer: sampled before any transition was added");
  std::vector<int64_t> rows(n);
  for (auto& r : rows) r = int64_t(rng.Index(uint64_t(size_)));
  return {Rows(obs_, rows, obs_dim_),         Rows(base_, rows, action_dim_),
          Rows(action_, rows, action_dim_),   Rows(reward_, rows, 1).view({-1}),
          Rows(next_obs_, rows, obs_dim_),    Rows(next_base_, rows, action_dim_),
          Rows(terminal_, rows, 1).view({-1})};
}

std::vector<ReplayBuffer::Field> ReplayBuffer::Fields() {
  return {{"obs", &obs_, obs_dim_},           {"base", &base_, action_dim_},
          {"action", &action_, action_dim_},  {"reward", &reward_, 1},
          {"next_obs", &next_obs_, obs_dim_}, {"next_base", &next_base_, action_dim_},
          {"terminal", &terminal_, 1}};
}

void ReplayBuffer::Save(const std::filesystem::path& path) {
  torch::serialize::OutputArchive archive;
  for (const Field& f : Fields())
    archive.write(f.name, torch::from_blob(f.data->data(), {size_, f.width}).clone());
  archive.write("next", torch::tensor(next_, torch::kInt64));
  archive.write("capacity", torch::tensor(capacity_, torch::kInt64));
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  const auto tmp = path.string() + ".tmp";
  archive.save_to(tmp);
  std::filesystem::rename(tmp, path);
}

void ReplayBuffer::Load(const std::filesystem::path& path) {
  if (!std::filesystem::is_regular_file(path))
    throw core::IoError("no replay buffer file at " + path.string());
  try {
    torch::serialize::InputArchive archive;
    archive.load_from(path.string());
    // Fresh tensors for every read: read() into a defined tensor of another shape misreads.
    std::vector<torch::Tensor> read;
    for (const Field& f : Fields()) {
      torch::Tensor x;
      archive.read(f.name, x);
      if (x.dim() != 2 || x.size(1) != f.width || x.size(0) > capacity_ ||
          (!read.empty() && x.size(0) != read.front().size(0)))
        throw core::Error(path.string() + ": replay buffer field '" + f.name +
                          "' does not fit a buffer of these sizes");
      read.push_back(x.contiguous());
    }
    torch::Tensor next, capacity;
    archive.read("next", next);
    archive.read("capacity", capacity);
    const int64_t saved_size = read.front().size(0);
    // A buffer that wrapped keeps its rows in ring order: only the same capacity continues it.
    if (saved_size == capacity.item<int64_t>() && capacity.item<int64_t>() != capacity_)
      throw core::Error(path.string() + ": a full replay buffer of capacity " +
                        std::to_string(capacity.item<int64_t>()) + " cannot continue as one of " +
                        std::to_string(capacity_));
    size_ = saved_size;
    next_ = next.item<int64_t>() % capacity_;
    const auto fields = Fields();
    for (std::size_t i = 0; i < fields.size(); ++i)
      std::copy_n(read[i].data_ptr<float>(), size_ * fields[i].width, fields[i].data->data());
  } catch (const c10::Error& e) {
    throw core::Error(path.string() + ": unreadable replay buffer (" + e.what_without_backtrace() +
                      ")");
  }
}

OffPolicyAgent::OffPolicyAgent(int obs_dim, int action_dim, const OffPolicyOptions& options)
    : obs_dim_(obs_dim),
      action_dim_(action_dim),
      options_(options),
      sac_(options.algorithm == "sac") {
  if (obs_dim <= 0 || action_dim <= 0)
    throw core::Error("off-policy agent: sizes must be positive");
  torch::manual_seed(options.seed);
  const int base = options.residual ? action_dim : 0;
  actor_ =
      Mlp(obs_dim + base, options.hidden, sac_ ? 2 * action_dim : action_dim, options.residual);
  q1_ = Mlp(obs_dim + base + action_dim, options.hidden, 1, false);
  q2_ = Mlp(obs_dim + base + action_dim, options.hidden, 1, false);
  actor_target_ = Copy(actor_);
  q1_target_ = Copy(q1_);
  q2_target_ = Copy(q2_);
  const torch::optim::AdamOptions adam(options.learning_rate);
  actor_opt_ = std::make_unique<torch::optim::Adam>(actor_->parameters(), adam);
  auto critic_params = q1_->parameters();
  for (auto& p : q2_->parameters()) critic_params.push_back(p);
  critic_opt_ = std::make_unique<torch::optim::Adam>(critic_params, adam);
  if (options.residual_dims > action_dim)
    throw core::Error("off-policy agent: residual_dims " + std::to_string(options.residual_dims) +
                      " exceeds the " + std::to_string(action_dim) + " action components");
  mask_ = torch::ones({action_dim});
  if (options.residual && options.residual_dims > 0) mask_.slice(0, options.residual_dims).zero_();
  log_alpha_ = torch::full({1}, std::log(options.initial_alpha), torch::requires_grad());
  alpha_opt_ = std::make_unique<torch::optim::Adam>(std::vector<torch::Tensor>{log_alpha_}, adam);
}

torch::Tensor OffPolicyAgent::ActorInput(const torch::Tensor& obs,
                                         const torch::Tensor& base) const {
  return options_.residual ? torch::cat({obs, base}, 1) : obs;
}

torch::Tensor OffPolicyAgent::CriticInput(const torch::Tensor& obs, const torch::Tensor& base,
                                          const torch::Tensor& action) const {
  return options_.residual ? torch::cat({obs, base, action}, 1) : torch::cat({obs, action}, 1);
}

std::pair<torch::Tensor, torch::Tensor> OffPolicyAgent::Squash(const torch::Tensor& out,
                                                               const torch::Tensor& base,
                                                               const torch::Tensor& eps) const {
  const double scale = options_.residual ? options_.residual_scale : 1.0;
  torch::Tensor u = out, log_prob;
  if (sac_) {
    const torch::Tensor mean = out.slice(1, 0, action_dim_);
    const torch::Tensor log_std = out.slice(1, action_dim_).clamp(-5.0, 2.0);
    u = eps.defined() ? mean + log_std.exp() * eps : mean;
    if (eps.defined()) {
      // Gaussian log-likelihood of u, then the change of variables through tanh. The scale's
      // constant Jacobian is left out, so that the entropy target (-dims) means the same for
      // any residual_scale.
      const torch::Tensor t = torch::tanh(u);
      log_prob = ((-0.5 * eps * eps - log_std - 0.5 * std::log(2 * M_PI)) * mask_).sum(1) -
                 (torch::log(1 - t * t + 1e-6) * mask_).sum(1);
    }
  }
  torch::Tensor action = scale * torch::tanh(u) * mask_;
  if (options_.residual) action = action + base;
  return {action.clamp(-1.0, 1.0), log_prob};
}

torch::Tensor OffPolicyAgent::Normal(int64_t rows, core::Rng& rng) const {
  torch::Tensor out = torch::empty({rows, action_dim_});
  float* o = out.data_ptr<float>();
  for (int64_t i = 0; i < rows * action_dim_; ++i) o[i] = float(rng.Normal());
  return out;
}

torch::Tensor OffPolicyAgent::ActBatch(const torch::Tensor& obs, const torch::Tensor& base) {
  torch::NoGradGuard no_grad;
  return Squash(actor_->forward(ActorInput(obs, base)), base, {}).first;
}

void OffPolicyAgent::Act(const float* obs, const float* base, bool explore, core::Rng& rng,
                         float* action) {
  torch::NoGradGuard no_grad;
  const torch::Tensor o = FromRow(obs, obs_dim_);
  const torch::Tensor b =
      options_.residual ? FromRow(base, action_dim_) : torch::zeros({1, action_dim_});
  const torch::Tensor out = actor_->forward(ActorInput(o, b));
  torch::Tensor a;
  if (sac_) {
    a = Squash(out, b, explore ? Normal(1, rng) : torch::Tensor()).first;
  } else {
    a = Squash(out, b, {}).first;
    if (explore) a = (a + options_.exploration_noise * Normal(1, rng) * mask_).clamp(-1.0, 1.0);
  }
  std::copy_n(a.data_ptr<float>(), action_dim_, action);
}

OffPolicyStats OffPolicyAgent::Update(const ReplayBuffer& buffer, core::Rng& rng,
                                      bool train_actor) {
  if (buffer.obs_dim() != obs_dim_ || buffer.action_dim() != action_dim_)
    throw core::Error("off-policy agent: the replay buffer holds other sizes");
  const auto b = buffer.Sample(options_.batch, rng);
  const int64_t n = options_.batch;
  OffPolicyStats stats;
  const double alpha = sac_ ? log_alpha_.exp().item<double>() : 0.0;
  stats.alpha = alpha;

  // Critics: the clipped double-Q target of the next state's action.
  torch::Tensor target;
  {
    torch::NoGradGuard no_grad;
    torch::Tensor next_action, next_log_prob;
    if (sac_) {
      std::tie(next_action, next_log_prob) =
          Squash(actor_->forward(ActorInput(b.next_obs, b.next_base)), b.next_base, Normal(n, rng));
    } else {
      const torch::Tensor noise = (options_.target_noise * Normal(n, rng))
                                      .clamp(-options_.noise_clip, options_.noise_clip) *
                                  mask_;
      next_action =
          (Squash(actor_target_->forward(ActorInput(b.next_obs, b.next_base)), b.next_base, {})
               .first +
           noise)
              .clamp(-1.0, 1.0);
    }
    const torch::Tensor in = CriticInput(b.next_obs, b.next_base, next_action);
    torch::Tensor next_q = torch::min(q1_target_->forward(in), q2_target_->forward(in)).view({-1});
    if (sac_) next_q = next_q - alpha * next_log_prob;
    target = b.reward + options_.gamma * (1 - b.terminal) * next_q;
  }
  const torch::Tensor in = CriticInput(b.obs, b.base, b.action);
  const torch::Tensor q1 = q1_->forward(in).view({-1}), q2 = q2_->forward(in).view({-1});
  const torch::Tensor critic_loss = torch::mse_loss(q1, target) + torch::mse_loss(q2, target);
  critic_opt_->zero_grad();
  critic_loss.backward();
  critic_opt_->step();
  stats.critic_loss = critic_loss.item<double>();
  stats.q = q1.mean().item<double>();
  ++updates_;

  // Critics alone: their targets still follow them, or they would regress onto the random
  // initial target networks for as long as the actor waits.
  if (!train_actor) {
    Polyak(q1_target_, q1_, options_.tau);
    Polyak(q2_target_, q2_, options_.tau);
    return stats;
  }
  if (!sac_ && updates_ % options_.policy_delay != 0) return stats;

  // Actor: up the first critic (TD3) or the soft value (SAC); the critics are held fixed.
  torch::Tensor action, log_prob;
  const torch::Tensor actor_out = actor_->forward(ActorInput(b.obs, b.base));
  std::tie(action, log_prob) = Squash(actor_out, b.base, sac_ ? Normal(n, rng) : torch::Tensor());
  const torch::Tensor pin = CriticInput(b.obs, b.base, action);
  torch::Tensor actor_loss;
  if (sac_) {
    const torch::Tensor q = torch::min(q1_->forward(pin), q2_->forward(pin)).view({-1});
    actor_loss = (alpha * log_prob - q).mean();
  } else {
    actor_loss = -q1_->forward(pin).mean();
  }
  if (options_.residual && options_.residual_penalty > 0)
    actor_loss = actor_loss + options_.residual_penalty * (action - b.base).pow(2).mean();
  actor_opt_->zero_grad();
  actor_loss.backward();
  actor_opt_->step();
  critic_opt_->zero_grad();  // the actor's backward pass left gradients in the critics
  stats.actor_loss = actor_loss.item<double>();
  stats.actor_updated = true;

  if (sac_ && options_.learn_alpha) {
    const torch::Tensor alpha_loss =
        -(log_alpha_ * (log_prob.detach() - mask_.sum().item<double>())).mean();
    alpha_opt_->zero_grad();
    alpha_loss.backward();
    alpha_opt_->step();
  }
  if (!sac_) Polyak(actor_target_, actor_, options_.tau);
  Polyak(q1_target_, q1_, options_.tau);
  Polyak(q2_target_, q2_, options_.tau);
  return stats;
}

std::vector<std::pair<const char*, torch::nn::Module*>> OffPolicyAgent::Modules() {
  return {{"actor", actor_.get()},
          {"actor_target", actor_target_.get()},
          {"q1", q1_.get()},
          {"q2", q2_.get()},
          {"q1_target", q1_target_.get()},
          {"q2_target", q2_target_.get()}};
}

std::vector<std::pair<const char*, torch::optim::Optimizer*>> OffPolicyAgent::Optimizers() {
  return {{"actor_opt", actor_opt_.get()},
          {"critic_opt", critic_opt_.get()},
          {"alpha_opt", alpha_opt_.get()}};
}

void OffPolicyAgent::Save(const std::filesystem::path& path) {
  torch::serialize::OutputArchive archive;
  for (const auto& [name, module] : Modules()) {
    torch::serialize::OutputArchive sub;
    module->save(sub);
    archive.write(name, sub);
  }
  for (const auto& [name, optimizer] : Optimizers()) {
    torch::serialize::OutputArchive sub;
    optimizer->save(sub);
    archive.write(name, sub);
  }
  archive.write("log_alpha", log_alpha_.detach());
  nlohmann::json state = {{"obs_dim", obs_dim_},
                          {"action_dim", action_dim_},
                          {"updates", updates_},
                          {"info", info_},
                          {"options", core::ToJson(options_)}};
  archive.write("twinforge_offpolicy", c10::IValue(state.dump()));
  if (path.has_parent_path()) std::filesystem::create_directories(path.parent_path());
  const auto tmp = path.string() + ".tmp";
  archive.save_to(tmp);
  std::filesystem::rename(tmp, path);
}

namespace {

// Opens an agent file and returns its state (sizes, options, counters).
nlohmann::json OpenAgentFile(const std::filesystem::path& path,
                             torch::serialize::InputArchive& archive) {
  if (!std::filesystem::is_regular_file(path))
    throw core::IoError("no off-policy agent file at " + path.string());
  c10::IValue text;
  try {
    archive.load_from(path.string());
    if (!archive.try_read("twinforge_offpolicy", text))
      throw core::Error(path.string() +
                        ": a LibTorch archive, but not a twinforge off-policy agent");
  } catch (const c10::Error& e) {
    throw core::Error(path.string() + ": not an off-policy agent (" + e.what_without_backtrace() +
                      ")");
  }
  const auto state = nlohmann::json::parse(text.toStringRef(), nullptr, false);
  if (state.is_discarded() || !state.contains("options") || !state.contains("obs_dim") ||
      !state.contains("action_dim") || !state.contains("updates"))
    throw core::Error(path.string() + ": an off-policy agent whose state is unreadable");
  return state;
}

}  // namespace

std::unique_ptr<OffPolicyAgent> OffPolicyAgent::Open(const std::filesystem::path& path) {
  torch::serialize::InputArchive archive;
  const nlohmann::json state = OpenAgentFile(path, archive);
  const auto options = core::ReadConfig<OffPolicyOptions>(
      core::ParseConfigText(state.at("options").dump(), path.string() + " (options)"));
  auto agent = std::make_unique<OffPolicyAgent>(state.at("obs_dim").get<int>(),
                                                state.at("action_dim").get<int>(), options);
  agent->Load(path);
  return agent;
}

void OffPolicyAgent::Load(const std::filesystem::path& path) {
  torch::serialize::InputArchive archive;
  const nlohmann::json state = OpenAgentFile(path, archive);
  const nlohmann::json mine = core::ToJson(options_);
  for (const char* key : {"algorithm", "residual", "hidden", "residual_dims"})
    if (state.at("options").value(key, nlohmann::json()) != mine.at(key))
      throw core::Error(path.string() + ": an agent with another " + key + " (" +
                        state.at("options").value(key, nlohmann::json()).dump() + ", not " +
                        mine.at(key).dump() + ")");
  if (state.at("obs_dim") != obs_dim_ || state.at("action_dim") != action_dim_)
    throw core::Error(path.string() + ": an agent of other sizes (obs " +
                      state.at("obs_dim").dump() + ", action " + state.at("action_dim").dump() +
                      ", not " + std::to_string(obs_dim_) + " and " + std::to_string(action_dim_) +
                      ")");
  try {
    for (const auto& [name, module] : Modules()) {
      torch::serialize::InputArchive sub;
      archive.read(name, sub);
      module->load(sub);
    }
    for (const auto& [name, optimizer] : Optimizers()) {
      torch::serialize::InputArchive sub;
      archive.read(name, sub);
      optimizer->load(sub);
    }
    torch::Tensor log_alpha;
    archive.read("log_alpha", log_alpha);
    torch::NoGradGuard no_grad;
    log_alpha_.copy_(log_alpha);
  } catch (const c10::Error& e) {
    throw core::Error(path.string() + ": unreadable off-policy agent (" +
                      e.what_without_backtrace() + ")");
  }
  updates_ = state.at("updates").get<int64_t>();
  info_ = state.value("info", nlohmann::json::object());
}

}  // namespace twinforge::learn
