#include "common/app.h"

#include <OpenImageIO/imageio.h>
#include <fmt/format.h>
#include <unistd.h>

#include <cstdlib>
#include <filesystem>
#include <map>

#include "common/version.h"
#include "dn/io/buffer_io.h"
#include "dn/io/output_files.h"
#include "dn/io/sha256.h"

namespace fs = std::filesystem;

namespace dn::cli {

std::string versionText(const std::string& tool, const Components& libraries) {
  std::string text =
      fmt::format("{} {} ({} {})\n", tool, DN_PROJECT_VERSION, DN_PROJECT_NAME, DN_GIT_DESCRIBE);
  for (const auto& [name, version] : libraries) text += fmt::format("  {} {}\n", name, version);
  return text;
}

Components commonComponents() {
  const int v = OIIO::openimageio_version();  // 20407 -> 2.4.7
  return {{"OpenImageIO", fmt::format("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)},
          {"fmt", fmt::format("{}.{}.{}", FMT_VERSION / 10000, FMT_VERSION / 100 % 100,
                              FMT_VERSION % 100)}};
}

std::string commandLine(int argc, char** argv) {
  std::string out;
  for (int i = 0; i < argc; ++i) {
    std::string a = argv[i];
    const bool plain = !a.empty() && a.find_first_not_of(
                                         "abcdefghijklmnopqrstuvwxyzABCDEFGHIJKLM"
                                         "NOPQRSTUVWXYZ0123456789_-+=.,/:@%") == std::string::npos;
    if (!plain) {
      std::string quoted = "'";
      for (char c : a) quoted += c == '\'' ? std::string("'\\''") : std::string(1, c);
      a = quoted + "'";
    }
    out += (i ? " " : "") + a;
  }
  return out;
}

void setToolProvenance(const std::string& tool, int argc, char** argv, const std::string& model,
                       std::string modelSha256) {
  const std::string software = fmt::format("{} {} ({})", tool, DN_PROJECT_VERSION, DN_GIT_DESCRIBE);
  const std::string command = commandLine(argc, argv);
  Attributes attributes = {
      {"Software", software}, {"ImageHistory", software + ": " + command}, {"dn:command", command}};
  if (!model.empty()) {
    attributes.emplace_back("dn:model", fs::path(model).filename().string());
    attributes.emplace_back("dn:model_sha256",
                            modelSha256.empty() ? sha256OfFile(model) : std::move(modelSha256));
  }
  setProvenance(std::move(attributes));
}

namespace {

fs::path executableDir() {
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  return ec ? fs::path() : exe.parent_path();
}

}  // namespace

std::string defaultModelPath() {
  if (const char* env = std::getenv("DN_MODEL"); env && *env) return env;
  std::vector<fs::path> places;
  if (const char* dir = std::getenv("DN_MODEL_DIR"); dir && *dir) places.push_back(dir);
  const fs::path exeDir = executableDir();
  if (!exeDir.empty()) {
    places.push_back(exeDir / ".." / "models");
    places.push_back(exeDir / ".." / "share" / DN_PROJECT_NAME / "models");
  }
  std::string looked;
  for (const auto& dir : places) {
    const fs::path model = (dir / "default.dnm").lexically_normal();
    std::error_code ec;
    if (fs::is_regular_file(model, ec)) return model.string();
    looked += (looked.empty() ? "" : ", ") + model.string();
  }
  throw IoError("no default model (looked for " + looked + "); give --model FILE or set DN_MODEL");
}

void checkReadable(const std::string& path) {
  std::error_code ec;
  const auto status = fs::status(path, ec);
  if (!fs::exists(status)) throw IoError(path + ": no such file");
  if (fs::is_directory(status)) throw IoError(path + ": is a folder, not a file");
  if (::access(path.c_str(), R_OK) != 0) throw IoError(path + ": not readable (permission denied)");
}

namespace {

// The absolute path with symlinks, "." and ".." resolved as far as it exists.
fs::path resolved(const std::string& path) {
  std::error_code ec;
  return fs::weakly_canonical(fs::absolute(path, ec), ec);
}

// The same file: the same inode when both exist, else the same resolved path.
bool sameFile(const std::string& a, const std::string& b) {
  std::error_code ec;
  if (fs::exists(a, ec) && fs::exists(b, ec)) return fs::equivalent(a, b, ec);
  return resolved(a) == resolved(b);
}

void checkWritableFolder(const std::string& output) {
  std::error_code ec;
  if (fs::is_directory(output, ec)) throw IoError(output + ": is a folder; give a file name");
  fs::path folder = fs::absolute(output, ec).parent_path();
  if (!fs::is_directory(folder, ec))
    throw IoError(output + ": the folder " + folder.string() + " does not exist");
  if (::access(folder.c_str(), W_OK | X_OK) != 0)
    throw IoError(output + ": the folder " + folder.string() + " is not writable");
}

}  // namespace

void checkFiles(const std::vector<std::string>& inputs, const std::vector<Output>& outputs,
                Inplace inplace) {
  for (const auto& input : inputs) checkReadable(input);
  std::map<fs::path, const Output*> seen;
  for (const auto& out : outputs) {
    for (const auto& input : inputs) {
      if (!sameFile(out.path, input)) continue;
      const bool own = sameFile(out.path, out.from);
      if (inplace == Inplace::Allow && own) continue;
      const std::string which = input == out.path ? "" : " (" + input + ")";
      throw IoError(out.path + ": is an input of this command" + which +
                    "; refusing to overwrite it" +
                    (inplace == Inplace::Offer && own ? " (use --inplace)" : ""));
    }
    auto [it, fresh] = seen.emplace(resolved(out.path), &out);
    if (!fresh)
      throw IoError(out.path + ": would be written twice, from " + it->second->from + " and from " +
                    out.from);
    checkWritableFolder(out.path);
  }
}

}  // namespace dn::cli
