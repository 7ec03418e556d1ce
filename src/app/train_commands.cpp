#include "app/train_commands.h"

#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>

#include "learn/bc.h"

namespace twinforge::app {

namespace {

struct BcCli {
  std::string demos, out;
  learn::BcOptions options;
};

}  // namespace

void AddTrainCommands(CLI::App& parent, int& exit_code) {
  auto* train = parent.add_subcommand("train", "learn policies");
  train->require_subcommand(1);
  auto cli = std::make_shared<BcCli>();
  auto* bc = train->add_subcommand(
      "bc", "behaviour cloning on demos' point clouds and proprioception (JSON report)");
  bc->add_option("--demos", cli->demos, "demos HDF5 (demos record --out)")
      ->required()
      ->check(CLI::ExistingFile);
  bc->add_option("--out", cli->out, "policy file to write; its loss curve goes beside it (.csv)")
      ->required();
  bc->add_option("--points", cli->options.sampling.n, "points per observation")
      ->check(CLI::Range(16, 8192));
  bc->add_option("--epochs", cli->options.max_epochs, "at most this many epochs")
      ->check(CLI::PositiveNumber);
  bc->add_option("--patience", cli->options.patience,
                 "stop after this many epochs without a better validation loss")
      ->check(CLI::PositiveNumber);
  bc->add_option("--batch", cli->options.batch, "minibatch size")->check(CLI::PositiveNumber);
  bc->add_option("--lr", cli->options.learning_rate, "Adam learning rate")
      ->check(CLI::Range(1e-6, 1.0));
  bc->add_option("--seed", cli->options.seed, "seed");
  bc->callback([cli, &exit_code] {
    core::Progress progress("bc", cli->options.max_epochs, "epochs");
    const learn::BcReport r = learn::TrainBc(cli->demos, cli->out, cli->options, &progress);
    progress.Finish();
    const nlohmann::json report = {{"policy", cli->out},
                                   {"curve", r.curve.string()},
                                   {"train_steps", r.train_samples},
                                   {"valid_steps", r.valid_samples},
                                   {"epochs", r.epochs},
                                   {"best_epoch", r.best_epoch},
                                   {"best_valid_loss", r.best_valid_loss},
                                   {"final_train_loss", r.final_train_loss},
                                   {"valid_accuracy", r.valid_accuracy},
                                   {"valid_mse", r.valid_mse},
                                   {"seconds", r.seconds}};
    std::cout << report.dump(2) << "\n";
    exit_code = 0;
  });
}

}  // namespace twinforge::app
