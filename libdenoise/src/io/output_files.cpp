#include "dn/io/output_files.h"

#include <unistd.h>

#include <atomic>
#include <csignal>
#include <cstring>

namespace dn {

namespace {

Attributes g_provenance;

// A fixed table, so the signal handler reads it without locks or allocation.
constexpr int kSlots = 16;
constexpr std::size_t kPathMax = 4096;
char g_paths[kSlots][kPathMax];
std::atomic<bool> g_used[kSlots];
char g_tool[64] = "dn";

void writeStderr(const char* text) {
  ssize_t ignored = ::write(STDERR_FILENO, text, std::strlen(text));
  (void)ignored;
}

extern "C" void onTerminatingSignal(int signal) {
  for (int i = 0; i < kSlots; ++i)
    if (g_used[i].load()) ::unlink(g_paths[i]);
  writeStderr(g_tool);
  writeStderr(signal == SIGINT ? ": stopped by SIGINT; no partial output left\n"
                               : ": stopped by SIGTERM; no partial output left\n");
  ::_exit(128 + signal);
}

}  // namespace

void setProvenance(Attributes attributes) { g_provenance = std::move(attributes); }
const Attributes& provenance() { return g_provenance; }

void trackTemporaryFile(const std::string& path) {
  if (path.size() >= kPathMax) return;
  for (int i = 0; i < kSlots; ++i) {
    if (g_used[i].load()) continue;
    std::memcpy(g_paths[i], path.c_str(), path.size() + 1);
    g_used[i].store(true);
    return;
  }
}

void untrackTemporaryFile(const std::string& path) {
  for (int i = 0; i < kSlots; ++i)
    if (g_used[i].load() && path == g_paths[i]) {
      g_used[i].store(false);
      return;
    }
}

void removeTemporaryFilesOnSignal(const char* tool) {
  std::strncpy(g_tool, tool, sizeof(g_tool) - 1);
  struct sigaction action {};
  action.sa_handler = onTerminatingSignal;
  sigemptyset(&action.sa_mask);
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);
}

}  // namespace dn
