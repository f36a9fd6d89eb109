#include "doctest_torch.h"
#include "tiny_models.h"

#include <netinet/in.h>
#include <signal.h>
#include <spawn.h>
#include <sys/socket.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <string>
#include <thread>

#include "dn/nn/model_file.h"
#include "dn/train/distributed.h"
#include "dn/train/trainer.h"

extern char** environ;

using namespace dn;
namespace fs = std::filesystem;

namespace {

const char* kWorkerEnv = "DN_TEST_DISTRIBUTED_WORKER";  // "rank world port mode output"
const char* kWorkerCase = "two-process worker";
constexpr int64_t kBatch = 4;

// A port nothing listens on right now (the kernel picks it).
int freePort() {
  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  REQUIRE(fd >= 0);
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  socklen_t length = sizeof(address);
  REQUIRE(bind(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0);
  REQUIRE(getsockname(fd, reinterpret_cast<sockaddr*>(&address), &length) == 0);
  close(fd);
  return ntohs(address.sin_port);
}

// Two convolutions with fixed weights drawn from `seed`.
torch::nn::Sequential tinyNet(uint64_t seed) {
  torch::manual_seed(seed);
  return torch::nn::Sequential(torch::nn::Conv2d(torch::nn::Conv2dOptions(3, 5, 3).padding(1)),
                               torch::nn::Tanh(),
                               torch::nn::Conv2d(torch::nn::Conv2dOptions(5, 3, 3).padding(1)));
}

// A fixed batch (input, target) of kBatch images.
std::pair<torch::Tensor, torch::Tensor> fixedBatch() {
  torch::manual_seed(42);
  auto input = torch::randn({kBatch, 3, 6, 7});
  auto target = torch::randn({kBatch, 3, 6, 7});
  return {input, target};
}

// Mean-squared-error gradients of `net` on images [first, first + count) of the batch.
std::vector<torch::Tensor> gradients(torch::nn::Sequential& net, int64_t first, int64_t count) {
  auto [input, target] = fixedBatch();
  net->zero_grad();
  torch::mse_loss(net->forward(input.narrow(0, first, count)), target.narrow(0, first, count))
      .backward();
  std::vector<torch::Tensor> grads;
  for (const auto& p : net->parameters()) grads.push_back(p.grad().clone());
  return grads;
}

double maxRelativeError(const torch::Tensor& value, const torch::Tensor& reference) {
  return ((value - reference).abs().max() / reference.abs().max()).item<double>();
}

DistributedOptions localOptions(int rank, int world, int port) {
  DistributedOptions o;
  o.world_size = world;
  o.rank = rank;
  o.master_port = port;
  o.connect_timeout = std::chrono::seconds(30);
  o.collective_timeout = std::chrono::seconds(30);
  return o;
}

// Starts this test binary as one worker rank; returns its pid.
pid_t spawnWorker(int rank, int world, int port, const std::string& mode,
                  const std::string& output) {
  const std::string exe = fs::read_symlink("/proc/self/exe").string();
  std::string selectCase = std::string("--test-case=") + kWorkerCase;
  std::string noSkip = "--no-skip";
  std::vector<char*> argv{const_cast<char*>(exe.c_str()), selectCase.data(), noSkip.data(),
                          nullptr};
  std::vector<std::string> env{std::string(kWorkerEnv) + "=" + std::to_string(rank) + " " +
                               std::to_string(world) + " " + std::to_string(port) + " " + mode +
                               " " + output};
  std::vector<char*> envp{env[0].data()};
  for (char** e = environ; *e; ++e) envp.push_back(*e);
  envp.push_back(nullptr);
  pid_t pid = 0;
  REQUIRE(posix_spawn(&pid, exe.c_str(), nullptr, nullptr, argv.data(), envp.data()) == 0);
  return pid;
}

// The worker's exit code, or -1 when it had to be killed after `limit`.
int waitForWorker(pid_t pid, std::chrono::seconds limit) {
  const auto deadline = std::chrono::steady_clock::now() + limit;
  int status = 0;
  while (waitpid(pid, &status, WNOHANG) == 0) {
    if (std::chrono::steady_clock::now() > deadline) {
      kill(pid, SIGKILL);
      waitpid(pid, &status, 0);
      return -1;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

constexpr int kTrainerSteps = 2;

// A tiny prior trained with the regression objective: no diffusion noise, so
// ranks and a single process see exactly the same loss on the same images.
ModelInfo tinyRegressionInfo() {
  ModelInfo info;
  info.base = tinyUNetConfig();
  info.has_control = false;
  info.objective = Objective::Regression;
  info.prediction = Prediction::X0;
  return info;
}

std::shared_ptr<ConditionalDenoiser> tinyDenoiser(uint64_t seed) {
  torch::manual_seed(seed);
  return buildDenoiser(tinyRegressionInfo());
}

TrainBatch fixedTrainBatch() {
  torch::manual_seed(9);
  auto target = torch::rand({kBatch, 3, 8, 8});
  auto noisy = (target + 0.2 * torch::randn({kBatch, 3, 8, 8})).clamp(0, 1);
  return {noisy, {}, target, {}};
}

}  // namespace

// Run only as a child of the two-process tests (skipped otherwise), in one mode:
//   gradients  start from rank-specific weights, take rank 0's by broadcast,
//              average the gradients of this rank's half of the batch, save them
//   trainer    two Trainer steps on this rank's half of the batch, save the weights
//   quit       stop right after joining and one barrier (so that rank 0's
//              side of the connection is made before this rank closes it)
TEST_CASE("two-process worker" * doctest::skip()) {
  const char* spec = std::getenv(kWorkerEnv);
  REQUIRE(spec != nullptr);
  int rank = 0, world = 0, port = 0;
  char mode[32] = {}, output[4096] = {};
  REQUIRE(std::sscanf(spec, "%d %d %d %31s %4095s", &rank, &world, &port, mode, output) == 5);
  torch::set_num_threads(1);
  auto averager = std::make_shared<GradientAverager>(localOptions(rank, world, port));
  const int64_t share = kBatch / world;
  if (std::string(mode) == "gradients") {
    auto net = tinyNet(100 + rank);
    averager->broadcastParameters(net->parameters());
    gradients(net, rank * share, share);
    averager->averageGradients(net->parameters());
    CHECK(averager->average(rank + 1.0) == doctest::Approx((world + 1) / 2.0));
    CHECK(averager->any(rank == world - 1));
    CHECK_FALSE(averager->any(false));
    averager->barrier();
    std::vector<torch::Tensor> saved;
    for (const auto& p : net->parameters()) saved.push_back(p.grad().clone());
    for (const auto& p : net->parameters()) saved.push_back(p.detach().clone());
    torch::save(saved, output);
  } else if (std::string(mode) == "trainer") {
    auto model = tinyDenoiser(100 + rank);
    Trainer trainer(model, tinyRegressionInfo(), TrainerOptions{});
    trainer.setGradientAverager(averager);
    const TrainBatch all = fixedTrainBatch();
    const TrainBatch mine{all.noisy.narrow(0, rank * share, share),
                          {},
                          all.target.narrow(0, rank * share, share),
                          {}};
    std::vector<torch::Tensor> saved;
    for (int i = 0; i < kTrainerSteps; ++i)
      saved.push_back(torch::tensor({trainer.step(mine).loss}, torch::kDouble));
    for (const auto& p : model->parameters()) saved.push_back(p.detach().clone());
    torch::save(saved, output);
  } else {
    REQUIRE(std::string(mode) == "quit");
    averager->barrier();
  }
}

TEST_CASE("two processes on loopback average to the whole batch's gradients") {
  const int port = freePort();
  const fs::path dir =
      fs::temp_directory_path() / ("dn_test_distributed_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string out0 = (dir / "rank0.pt").string(), out1 = (dir / "rank1.pt").string();
  const pid_t rank1 = spawnWorker(1, 2, port, "gradients", out1);  // waits for rank 0's store
  const pid_t rank0 = spawnWorker(0, 2, port, "gradients", out0);
  REQUIRE(waitForWorker(rank0, std::chrono::seconds(60)) == 0);
  REQUIRE(waitForWorker(rank1, std::chrono::seconds(60)) == 0);

  auto reference = tinyNet(100);  // rank 0's weights, which the broadcast gave both ranks
  const auto expected = gradients(reference, 0, kBatch);
  const auto params = reference->parameters();
  for (const auto& path : {out0, out1}) {
    std::vector<torch::Tensor> saved;
    torch::load(saved, path);
    REQUIRE(saved.size() == 2 * params.size());
    for (size_t i = 0; i < params.size(); ++i) {
      CAPTURE(path);
      CAPTURE(i);
      CHECK(maxRelativeError(saved[i], expected[i]) < 1e-5);
      CHECK(torch::equal(saved[params.size() + i], params[i].detach()));
    }
  }
  fs::remove_all(dir);
}

TEST_CASE("world size 1 changes nothing and needs no network") {
  DistributedOptions o;
  o.master_addr = "no-such-host.invalid";  // would fail if anything were resolved
  GradientAverager averager(o);
  auto net = tinyNet(5);
  const auto before = gradients(net, 0, kBatch);
  averager.broadcastParameters(net->parameters());
  averager.averageGradients(net->parameters());
  const auto params = net->parameters();
  for (size_t i = 0; i < params.size(); ++i) CHECK(torch::equal(params[i].grad(), before[i]));
  CHECK(averager.average(2.5) == 2.5);
  CHECK(averager.any(true));
  CHECK_FALSE(averager.any(false));
  averager.barrier();
  CHECK(averager.isMain());
}

TEST_CASE("bad rank, world size or port is a one-line error") {
  auto message = [](int rank, int world, int port) {
    try {
      GradientAverager averager(localOptions(rank, world, port));
    } catch (const std::runtime_error& error) {
      return std::string(error.what());
    }
    return std::string("no error");
  };
  CHECK(message(2, 2, 29500) == "distributed: rank 2 is outside 0..1 for world size 2");
  CHECK(message(-1, 2, 29500) == "distributed: rank -1 is outside 0..1 for world size 2");
  CHECK(message(0, 0, 29500) == "distributed: world size must be at least 1, got 0");
  CHECK(message(1, 2, 70000) == "distributed: master port must be in 1..65535, got 70000");
}

TEST_CASE("a master that never answers is an error after the connect timeout") {
  DistributedOptions o = localOptions(1, 2, freePort());
  o.connect_timeout = std::chrono::milliseconds(1500);
  const auto start = std::chrono::steady_clock::now();
  std::string what;
  try {
    GradientAverager averager(o);
  } catch (const std::runtime_error& error) {
    what = error.what();
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  CAPTURE(what);
  CHECK(what.rfind("distributed: rank 1 cannot reach the master at 127.0.0.1:", 0) == 0);
  CHECK(what.find('\n') == std::string::npos);
  CHECK(seconds < 15);
}

TEST_CASE("rank 0 alone is an error after the connect timeout") {
  DistributedOptions o = localOptions(0, 2, freePort());
  o.connect_timeout = std::chrono::milliseconds(1500);
  std::string what;
  try {
    GradientAverager averager(o);
  } catch (const std::runtime_error& error) {
    what = error.what();
  }
  CAPTURE(what);
  CHECK(what.rfind("distributed: only 1 of 2 ranks joined 127.0.0.1:", 0) == 0);
  CHECK(what.find("within 1.5 s") != std::string::npos);
}

TEST_CASE("a rank that stops makes the next collective an error, not a hang") {
  const int port = freePort();
  const pid_t rank1 = spawnWorker(1, 2, port, "quit", "-");
  GradientAverager averager(localOptions(0, 2, port));
  averager.barrier();  // both joined; then rank 1 stops
  REQUIRE(waitForWorker(rank1, std::chrono::seconds(60)) == 0);
  auto net = tinyNet(3);
  gradients(net, 0, kBatch);
  std::string what;
  try {
    averager.averageGradients(net->parameters());
  } catch (const std::runtime_error& error) {
    what = error.what();
  }
  CAPTURE(what);
  CHECK(what.rfind("distributed: rank 0: gradient averaging failed, another rank has probably "
                   "stopped (",
                   0) == 0);
}

TEST_CASE("two-process Trainer steps equal one process's steps on the whole batch") {
  const int port = freePort();
  const fs::path dir =
      fs::temp_directory_path() / ("dn_test_distributed_trainer_" + std::to_string(getpid()));
  fs::create_directories(dir);
  const std::string out0 = (dir / "rank0.pt").string(), out1 = (dir / "rank1.pt").string();
  const pid_t rank1 = spawnWorker(1, 2, port, "trainer", out1);
  const pid_t rank0 = spawnWorker(0, 2, port, "trainer", out0);
  REQUIRE(waitForWorker(rank0, std::chrono::seconds(60)) == 0);
  REQUIRE(waitForWorker(rank1, std::chrono::seconds(60)) == 0);

  auto model = tinyDenoiser(100);  // rank 0's initial weights
  Trainer single(model, tinyRegressionInfo(), TrainerOptions{});
  std::vector<double> losses;
  for (int i = 0; i < kTrainerSteps; ++i) losses.push_back(single.step(fixedTrainBatch()).loss);
  const auto params = model->parameters();

  std::vector<torch::Tensor> rank0Saved, rank1Saved;
  torch::load(rank0Saved, out0);
  torch::load(rank1Saved, out1);
  REQUIRE(rank0Saved.size() == kTrainerSteps + params.size());
  REQUIRE(rank1Saved.size() == rank0Saved.size());
  for (int i = 0; i < kTrainerSteps; ++i) {
    CHECK(rank0Saved[i].item<double>() == doctest::Approx(losses[i]).epsilon(1e-5));
    CHECK(rank1Saved[i].item<double>() == rank0Saved[i].item<double>());
  }
  double largestDifference = 0;
  for (size_t i = 0; i < params.size(); ++i) {
    const auto& weight0 = rank0Saved[kTrainerSteps + i];
    CHECK(torch::equal(weight0, rank1Saved[kTrainerSteps + i]));  // ranks stay identical
    largestDifference =
        std::max(largestDifference, (weight0 - params[i].detach()).abs().max().item<double>());
  }
  CAPTURE(largestDifference);
  CHECK(largestDifference < 1e-5);
  fs::remove_all(dir);
}
