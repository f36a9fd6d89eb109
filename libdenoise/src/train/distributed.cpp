#include "dn/train/distributed.h"

#include <arpa/inet.h>
#include <netdb.h>
#include <sys/socket.h>
#include <unistd.h>

#include <cstdlib>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <torch/csrc/distributed/c10d/ProcessGroupGloo.hpp>
#include <torch/csrc/distributed/c10d/TCPStore.hpp>

namespace dn {

struct GradientAverager::Group {
  c10::intrusive_ptr<c10d::TCPStore> store;
  c10::intrusive_ptr<c10d::ProcessGroupGloo> group;
};

namespace {

std::runtime_error distributedError(const std::string& message) {
  return std::runtime_error("distributed: " + message);
}

// The first line of a LibTorch error, without its backtrace.
std::string firstLine(const std::exception& error) {
  const auto* c10Error = dynamic_cast<const c10::Error*>(&error);
  const std::string what = c10Error ? c10Error->what_without_backtrace() : error.what();
  return what.substr(0, what.find('\n'));
}

std::string secondsText(std::chrono::milliseconds duration) {
  std::ostringstream text;
  text << std::chrono::duration<double>(duration).count() << " s";
  return text.str();
}

std::string masterName(const DistributedOptions& o) {
  return o.master_addr + ":" + std::to_string(o.master_port);
}

void checkOptions(const DistributedOptions& o) {
  if (o.world_size < 1)
    throw distributedError("world size must be at least 1, got " + std::to_string(o.world_size));
  if (o.rank < 0 || o.rank >= o.world_size)
    throw distributedError("rank " + std::to_string(o.rank) + " is outside 0.." +
                           std::to_string(o.world_size - 1) + " for world size " +
                           std::to_string(o.world_size));
  if (o.world_size > 1 && (o.master_port < 1 || o.master_port > 65535))
    throw distributedError("master port must be in 1..65535, got " + std::to_string(o.master_port));
  if (o.world_size > 1 && o.master_addr.empty()) throw distributedError("master address is empty");
}

// This machine's address on the route to the master (a UDP connect sends
// nothing), so Gloo listens where the other ranks can reach it: loopback for a
// local master, the right network interface for a remote one.
std::string localAddressTowards(const DistributedOptions& o) {
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_DGRAM;
  addrinfo* found = nullptr;
  const int status =
      getaddrinfo(o.master_addr.c_str(), std::to_string(o.master_port).c_str(), &hints, &found);
  if (status != 0)
    throw distributedError("cannot resolve master address '" + o.master_addr +
                           "': " + gai_strerror(status));
  std::string local;
  for (addrinfo* a = found; a && local.empty(); a = a->ai_next) {
    const int fd = socket(a->ai_family, a->ai_socktype, 0);
    if (fd < 0) continue;
    sockaddr_storage self{};
    socklen_t length = sizeof(self);
    char text[INET6_ADDRSTRLEN] = {};
    if (connect(fd, a->ai_addr, a->ai_addrlen) == 0 &&
        getsockname(fd, reinterpret_cast<sockaddr*>(&self), &length) == 0) {
      const void* address =
          self.ss_family == AF_INET
              ? static_cast<const void*>(&reinterpret_cast<sockaddr_in*>(&self)->sin_addr)
              : static_cast<const void*>(&reinterpret_cast<sockaddr_in6*>(&self)->sin6_addr);
      if (inet_ntop(self.ss_family, address, text, sizeof(text))) local = text;
    }
    close(fd);
  }
  freeaddrinfo(found);
  if (local.empty()) throw distributedError("no network route to the master " + masterName(o));
  return local;
}

std::shared_ptr<::gloo::transport::Device> glooDevice(const DistributedOptions& o) {
  // The same override PyTorch honours, for machines with several interfaces.
  if (const char* interface = std::getenv("GLOO_SOCKET_IFNAME"); interface && *interface)
    return c10d::ProcessGroupGloo::createDeviceForInterface(interface);
  return c10d::ProcessGroupGloo::createDeviceForHostname(localAddressTowards(o));
}

c10::intrusive_ptr<c10d::TCPStore> connectStore(const DistributedOptions& o) {
  c10d::TCPStoreOptions so;
  so.port = static_cast<std::uint16_t>(o.master_port);
  so.isServer = o.rank == 0;
  so.numWorkers = static_cast<std::size_t>(o.world_size);
  so.waitWorkers = false;  // its wait gives up silently; waitForAllRanks reports instead
  so.timeout = o.connect_timeout;
  try {
    return c10::make_intrusive<c10d::TCPStore>(o.master_addr, so);
  } catch (const std::exception& error) {  // c10::Error or c10d's socket errors
    if (o.rank == 0)
      throw distributedError("rank 0 cannot listen on " + masterName(o) + " (" + firstLine(error) +
                             ")");
    throw distributedError("rank " + std::to_string(o.rank) + " cannot reach the master at " +
                           masterName(o) + " within " + secondsText(o.connect_timeout) + " (" +
                           firstLine(error) + ")");
  }
}

// Every rank registers in the store; rank 0 waits for all of them, so a missing
// or duplicated rank is reported here rather than as a stalled Gloo rendezvous.
void waitForAllRanks(c10d::TCPStore& store, const DistributedOptions& o) {
  const std::string rank = std::to_string(o.rank);
  if (store.add("dn/rank/" + rank, 1) > 1)
    throw distributedError("rank " + rank + " has already joined " + masterName(o) +
                           " from another process");
  store.add("dn/joined", 1);
  if (o.rank == 0) {
    const auto deadline = std::chrono::steady_clock::now() + o.connect_timeout;
    int64_t joined = 0;
    while ((joined = store.add("dn/joined", 0)) < o.world_size) {
      if (std::chrono::steady_clock::now() > deadline)
        throw distributedError("only " + std::to_string(joined) + " of " +
                               std::to_string(o.world_size) + " ranks joined " + masterName(o) +
                               " within " + secondsText(o.connect_timeout));
      std::this_thread::sleep_for(std::chrono::milliseconds(20));
    }
    store.set("dn/all_joined", {1});
  } else {
    try {
      store.wait({"dn/all_joined"}, o.connect_timeout);
    } catch (const std::exception& error) {
      throw distributedError("rank " + rank + " reached " + masterName(o) +
                             " but not every rank joined within " + secondsText(o.connect_timeout) +
                             " (" + firstLine(error) + ")");
    }
  }
}

// All tensors as one contiguous 1-D buffer (they must share a dtype).
torch::Tensor flatten(const std::vector<torch::Tensor>& tensors) {
  std::vector<torch::Tensor> pieces;
  pieces.reserve(tensors.size());
  for (const auto& t : tensors) {
    if (t.scalar_type() != tensors.front().scalar_type())
      throw distributedError("tensors to combine must share one dtype");
    pieces.push_back(t.detach().reshape({-1}));
  }
  return torch::cat(pieces);
}

void unflattenInto(const torch::Tensor& flat, const std::vector<torch::Tensor>& tensors) {
  int64_t offset = 0;
  for (const auto& t : tensors) {
    const int64_t n = t.numel();
    t.detach().copy_(flat.slice(0, offset, offset + n).view(t.sizes()));
    offset += n;
  }
}

// Runs one collective to completion; a rank that died or hung shows up here.
void complete(const c10::intrusive_ptr<c10d::Work>& work, const DistributedOptions& o,
              const char* what) {
  try {
    work->wait();
  } catch (const std::exception& error) {
    throw distributedError("rank " + std::to_string(o.rank) + ": " + what +
                           " failed, another rank has probably stopped (" + firstLine(error) + ")");
  }
}

}  // namespace

GradientAverager::GradientAverager(const DistributedOptions& options) : options_(options) {
  checkOptions(options_);
  if (options_.world_size == 1) return;
  group_ = std::make_unique<Group>();
  group_->store = connectStore(options_);
  waitForAllRanks(*group_->store, options_);
  auto glooOptions = c10d::ProcessGroupGloo::Options::create(options_.collective_timeout);
  glooOptions->devices.push_back(glooDevice(options_));
  try {
    group_->group = c10::make_intrusive<c10d::ProcessGroupGloo>(group_->store, options_.rank,
                                                                options_.world_size, glooOptions);
  } catch (const std::exception& error) {
    throw distributedError("rank " + std::to_string(options_.rank) +
                           " could not connect to the other ranks (" + firstLine(error) + ")");
  }
}

GradientAverager::~GradientAverager() = default;

void GradientAverager::averageGradients(const std::vector<torch::Tensor>& params) {
  if (!group_) return;
  std::vector<torch::Tensor> grads;
  for (const auto& p : params)
    if (p.grad().defined()) grads.push_back(p.grad());
  if (grads.empty()) return;
  torch::NoGradGuard noGrad;
  std::vector<torch::Tensor> buffer{flatten(grads)};
  complete(group_->group->allreduce(buffer), options_, "gradient averaging");
  buffer[0].div_(options_.world_size);
  unflattenInto(buffer[0], grads);
}

void GradientAverager::broadcastParameters(const std::vector<torch::Tensor>& params) {
  if (!group_ || params.empty()) return;
  torch::NoGradGuard noGrad;
  std::vector<torch::Tensor> buffer{flatten(params)};
  complete(group_->group->broadcast(buffer), options_, "broadcast from rank 0");
  unflattenInto(buffer[0], params);
}

double GradientAverager::average(double value) {
  if (!group_) return value;
  std::vector<torch::Tensor> buffer{torch::tensor({value}, torch::kDouble)};
  complete(group_->group->allreduce(buffer), options_, "averaging a value");
  return buffer[0].item<double>() / options_.world_size;
}

bool GradientAverager::any(bool flag) {
  if (!group_) return flag;
  std::vector<torch::Tensor> buffer{torch::tensor({flag ? 1 : 0}, torch::kInt)};
  complete(group_->group->allreduce(buffer, c10d::AllreduceOptions{c10d::ReduceOp::MAX}), options_,
           "exchanging a flag");
  return buffer[0].item<int>() > 0;
}

void GradientAverager::barrier() {
  if (group_) complete(group_->group->barrier(), options_, "barrier");
}

}  // namespace dn
