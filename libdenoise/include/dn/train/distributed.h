// Data-parallel training on CPU: every process (rank) computes gradients on its
// own share of the data, then GradientAverager averages them across processes
// through LibTorch's c10d with the Gloo backend, so every rank takes the same
// optimizer step. Rank 0 hosts the rendezvous (a c10d TCPStore) at
// master_addr:master_port. With world_size 1 every call is a no-op and no
// network is touched.
#pragma once

#include <chrono>
#include <memory>
#include <string>
#include <vector>

#include <torch/torch.h>

namespace dn {

struct DistributedOptions {
  int world_size = 1;
  int rank = 0;
  std::string master_addr = "127.0.0.1";
  int master_port = 29500;
  // How long rank 0 waits for the others to join, and the others for rank 0.
  std::chrono::milliseconds connect_timeout = std::chrono::minutes(5);
  // How long one collective may wait for the slowest rank (rank 0 validates
  // and writes checkpoints while the others wait in the next collective).
  std::chrono::milliseconds collective_timeout = std::chrono::minutes(30);
};

class GradientAverager {
 public:
  // Joins the group; throws std::runtime_error (one line) for a bad rank, world
  // size or port, or when the group does not form within connect_timeout.
  explicit GradientAverager(const DistributedOptions& options);
  ~GradientAverager();
  GradientAverager(const GradientAverager&) = delete;
  GradientAverager& operator=(const GradientAverager&) = delete;

  int worldSize() const { return options_.world_size; }
  int rank() const { return options_.rank; }
  bool isMain() const { return options_.rank == 0; }

  // Replaces every defined .grad() with its mean over all ranks (one flat
  // allreduce). All ranks must pass the same parameters in the same order.
  void averageGradients(const std::vector<torch::Tensor>& params);
  // Overwrites every rank's tensors (e.g. parameters) in place with rank 0's.
  void broadcastParameters(const std::vector<torch::Tensor>& params);
  // The mean of `value` over all ranks (e.g. the loss for a log).
  double average(double value);
  // True on every rank when `flag` is true on at least one (e.g. a stop request).
  bool any(bool flag);
  // Returns once every rank has called it.
  void barrier();

 private:
  struct Group;  // c10d and Gloo stay out of this header
  DistributedOptions options_;
  std::unique_ptr<Group> group_;  // null when world_size is 1
};

}  // namespace dn
