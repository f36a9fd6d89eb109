#include "dn/nn/model_file.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iomanip>
#include <random>
#include <sstream>

#include "dn/diffusion/refine.h"
#include "dn/tonemap.h"

namespace dn {
namespace {

constexpr const char* kMagic = "DNCORE-ARCHIVE";
constexpr size_t kMaxHeaderLine = 256;

uint64_t fnv1a64(std::string_view a, std::string_view b) {
  uint64_t hash = 1469598103934665603ull;
  for (std::string_view part : {a, b})
    for (unsigned char byte : part) {
      hash ^= byte;
      hash *= 1099511628211ull;
    }
  return hash;
}

std::string hex64(uint64_t value) {
  std::ostringstream out;
  out << std::hex << std::setw(16) << std::setfill('0') << value;
  return out.str();
}

// Reads key=value metadata with typed accessors that report the file and key.
class KeyValues {
 public:
  KeyValues(const std::string& text, const std::string& source) : source_(source) {
    std::stringstream stream(text);
    std::string line;
    int number = 0;
    while (std::getline(stream, line)) {
      ++number;
      if (line.empty() || line[0] == '#') continue;
      const auto eq = line.find('=');
      if (eq == std::string::npos || eq == 0)
        fail("metadata line " + std::to_string(number) + " is not key=value");
      values_[line.substr(0, eq)] = line.substr(eq + 1);
    }
  }
  [[noreturn]] void fail(const std::string& problem) const {
    throw ModelError(source_ + ": " + problem);
  }
  bool has(const std::string& key) const { return values_.count(key) != 0; }
  const std::map<std::string, std::string>& all() const { return values_; }
  std::string text(const std::string& key) const {
    auto it = values_.find(key);
    if (it == values_.end()) fail("metadata lacks '" + key + "'");
    return it->second;
  }
  int64_t integer(const std::string& key) const { return parseInt(key, text(key)); }
  bool flag(const std::string& key) const { return integer(key) != 0; }
  std::vector<int64_t> integers(const std::string& key) const {
    std::vector<int64_t> out;
    for (const auto& item : splitList(text(key))) out.push_back(parseInt(key, item));
    return out;
  }

 private:
  int64_t parseInt(const std::string& key, const std::string& value) const {
    size_t used = 0;
    long long parsed = 0;
    try {
      parsed = std::stoll(value, &used);
    } catch (const std::exception&) {
      used = 0;
    }
    if (used == 0 || used != value.size())
      fail("metadata '" + key + "' is not an integer: " + value);
    return parsed;
  }
  std::string source_;
  std::map<std::string, std::string> values_;
};

// A file mapped read-only while it is parsed: the tensor archive is read where
// it lies instead of being copied into memory twice first (0.15 s of a 35 MB
// model's load).
class MappedFile {
 public:
  explicit MappedFile(const std::string& path) {
    const int fd = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd < 0) throw ModelError(path + ": cannot open for reading");
    struct stat info {};
    if (::fstat(fd, &info) == 0) size_ = static_cast<std::size_t>(info.st_size);
    void* data = size_ > 0 ? ::mmap(nullptr, size_, PROT_READ, MAP_PRIVATE, fd, 0) : nullptr;
    ::close(fd);
    if (data == MAP_FAILED) throw ModelError(path + ": read error");
    data_ = static_cast<const char*>(data);
  }
  ~MappedFile() {
    if (data_) ::munmap(const_cast<char*>(data_), size_);
  }
  MappedFile(const MappedFile&) = delete;
  MappedFile& operator=(const MappedFile&) = delete;
  std::string_view bytes() const { return {data_ ? data_ : "", size_}; }

 private:
  const char* data_ = nullptr;
  std::size_t size_ = 0;
};

// Next '\n'-terminated header line from `data` at `pos`, bounded in length.
bool headerLine(std::string_view data, size_t& pos, std::string& line) {
  const auto end = data.find('\n', pos);
  if (end == std::string_view::npos || end - pos > kMaxHeaderLine) return false;
  line = data.substr(pos, end - pos);
  pos = end + 1;
  return true;
}

bool headerValue(std::string_view data, size_t& pos, const std::string& key, std::string& value) {
  std::string line;
  if (!headerLine(data, pos, line) || line.rfind(key + " ", 0) != 0) return false;
  value = line.substr(key.size() + 1);
  return true;
}

bool parseSize(const std::string& text, uint64_t& value) {
  if (text.empty() || text.size() > 19 || text.find_first_not_of("0123456789") != std::string::npos)
    return false;
  value = std::stoull(text);
  return true;
}

}  // namespace

void writeAtomically(const std::string& path, const std::function<void(std::ostream&)>& write) {
  namespace fs = std::filesystem;
  const fs::path target(path);
  std::random_device random;
  const fs::path temp = target.string() + ".tmp" + std::to_string(random());
  {
    std::ofstream out(temp, std::ios::binary | std::ios::trunc);
    if (!out) throw ModelError(path + ": cannot open " + temp.string() + " for writing");
    write(out);
    out.flush();
    if (!out) {
      std::error_code ignored;
      fs::remove(temp, ignored);
      throw ModelError(path + ": write failed (disk full?)");
    }
  }
  std::error_code error;
  fs::rename(temp, target, error);
  if (error) {
    std::error_code ignored;
    fs::remove(temp, ignored);
    throw ModelError(path + ": cannot rename temporary file: " + error.message());
  }
}

std::string joinInts(const std::vector<int64_t>& values) {
  std::string text;
  for (size_t i = 0; i < values.size(); ++i) text += (i ? "," : "") + std::to_string(values[i]);
  return text;
}

std::string joinStrings(const std::vector<std::string>& values) {
  std::string text;
  for (size_t i = 0; i < values.size(); ++i) text += (i ? "," : "") + values[i];
  return text;
}

std::vector<std::string> splitList(const std::string& text) {
  std::vector<std::string> items;
  std::stringstream stream(text);
  std::string item;
  while (std::getline(stream, item, ','))
    if (!item.empty()) items.push_back(item);
  return items;
}

namespace {

std::string oidnInfoToText(const ModelInfo& info) {
  std::ostringstream out;
  out << "base=oidn\n"
      << "oidn.arch=" << oidnArchName(info.oidn.arch) << "\n"
      << "oidn.input_sets=" << joinStrings(info.oidn.input_sets) << "\n"
      << "input_buffers=" << joinStrings(info.input_buffers) << "\n"
      << "control=" << (info.has_control ? 1 : 0) << "\n";
  if (info.has_control) {
    const OidnControlConfig& c = info.oidn.control;
    std::ostringstream sigmas;
    sigmas << std::setprecision(9);
    for (size_t i = 0; i < info.oidn.sigmas.size(); ++i)
      sigmas << (i ? "," : "") << info.oidn.sigmas[i];
    out << "control.input_set=" << c.input_set << "\n"
        << "control.extra_buffers=" << joinStrings(c.extra_buffers) << "\n"
        << "control.hint_channels=" << c.hint_channels << "\n"
        << "control.diffusion=" << (c.diffusion ? 1 : 0) << "\n"
        << "control.sigmas=" << sigmas.str() << "\n";
  }
  return out.str();
}

void oidnInfoFromText(const KeyValues& kv, ModelInfo& info) {
  info.base_kind = BaseKind::Oidn;
  try {
    info.oidn.arch = oidnArchFromName(kv.text("oidn.arch"));
    info.oidn.input_sets = splitList(kv.text("oidn.input_sets"));
    if (info.oidn.input_sets.empty()) throw std::invalid_argument("oidn.input_sets is empty");
    for (const auto& set : info.oidn.input_sets) oidnInputSet(set);
  } catch (const std::invalid_argument& error) {
    kv.fail(error.what());
  }
  info.input_buffers = splitList(kv.text("input_buffers"));
  info.has_control = kv.has("control") && kv.integer("control") != 0;
  info.objective = Objective::Regression;
  if (!info.has_control) return;
  OidnControlConfig& c = info.oidn.control;
  c.input_set = kv.text("control.input_set");
  c.extra_buffers = splitList(kv.text("control.extra_buffers"));
  c.hint_channels = kv.integer("control.hint_channels");
  c.diffusion = kv.integer("control.diffusion") != 0;
  try {
    for (const auto& s : splitList(kv.text("control.sigmas")))
      info.oidn.sigmas.push_back(std::stod(s));
    c.validate();
    checkSigmas(info.oidn.sigmas);
    if (std::find(info.oidn.input_sets.begin(), info.oidn.input_sets.end(), c.input_set) ==
        info.oidn.input_sets.end())
      throw std::invalid_argument("control.input_set is not among oidn.input_sets");
  } catch (const std::logic_error& error) {  // std::stod's and validate()'s
    kv.fail(error.what());
  }
  if (c.diffusion) info.objective = Objective::Diffusion;
}

void diffusionInfoFromText(const KeyValues& kv, ModelInfo& info) {
  auto& b = info.base;
  b.in_channels = kv.integer("base.in_channels");
  b.cond_channels = kv.integer("base.cond_channels");
  b.out_channels = kv.integer("base.out_channels");
  b.base_channels = kv.integer("base.base_channels");
  b.channel_mults = kv.integers("base.channel_mults");
  b.res_blocks = kv.integer("base.res_blocks");
  b.attention_levels = kv.integers("base.attention_levels");
  b.middle_attention = kv.flag("base.middle_attention");
  b.head_channels = kv.integer("base.head_channels");
  b.norm_groups = kv.integer("base.norm_groups");
  info.has_control = kv.flag("control");
  if (info.has_control) {
    auto& c = info.control;
    c.aux_channels = kv.integer("control.aux_channels");
    c.radiance_channels = kv.integer("control.radiance_channels");
    c.hint_channels = kv.integer("control.hint_channels");
    c.hint_layers = kv.integer("control.hint_layers");
  }
  info.input_buffers = splitList(kv.text("input_buffers"));
  info.tonemap = kv.text("tonemap");
  if (kv.has("objective")) {
    const std::string objective = kv.text("objective");
    if (objective != "regression") kv.fail("unknown objective '" + objective + "'");
    info.objective = Objective::Regression;
  }
  info.schedule_steps = kv.integer("schedule_steps");
  info.respacing = kv.text("respacing");
  try {
    b.validate();
    if (info.has_control) info.control.validate();
    tonemap::curveFromName(info.tonemap);
    info.prediction = predictionFromName(kv.text("prediction"));
    info.schedule = scheduleKindFromName(kv.text("schedule"));
    if (info.schedule_steps < 2 || info.schedule_steps > 100000)
      throw std::invalid_argument("schedule_steps out of range");
    respacedTimesteps(info.schedule_steps, info.respacing);
  } catch (const std::invalid_argument& error) {
    kv.fail(error.what());
  }
}

void notesToText(const ModelInfo& info, std::ostream& out) {
  for (const auto& [key, value] : info.notes) {
    if (value.find('\n') != std::string::npos || key.find('=') != std::string::npos)
      throw std::invalid_argument("model note '" + key +
                                  "' must be one line without '=' in its key");
    out << "note." << key << "=" << value << "\n";
  }
}

}  // namespace

std::string modelInfoToText(const ModelInfo& info) {
  std::ostringstream out;
  if (info.base_kind == BaseKind::Oidn) {
    out << oidnInfoToText(info);
    notesToText(info, out);
    return out.str();
  }
  const auto& b = info.base;
  out << "base.in_channels=" << b.in_channels << "\n"
      << "base.cond_channels=" << b.cond_channels << "\n"
      << "base.out_channels=" << b.out_channels << "\n"
      << "base.base_channels=" << b.base_channels << "\n"
      << "base.channel_mults=" << joinInts(b.channel_mults) << "\n"
      << "base.res_blocks=" << b.res_blocks << "\n"
      << "base.attention_levels=" << joinInts(b.attention_levels) << "\n"
      << "base.middle_attention=" << (b.middle_attention ? 1 : 0) << "\n"
      << "base.head_channels=" << b.head_channels << "\n"
      << "base.norm_groups=" << b.norm_groups << "\n"
      << "control=" << (info.has_control ? 1 : 0) << "\n";
  if (info.has_control) {
    const auto& c = info.control;
    out << "control.aux_channels=" << c.aux_channels << "\n"
        << "control.radiance_channels=" << c.radiance_channels << "\n"
        << "control.hint_channels=" << c.hint_channels << "\n"
        << "control.hint_layers=" << c.hint_layers << "\n";
  }
  out << "input_buffers=" << joinStrings(info.input_buffers) << "\n"
      << "tonemap=" << info.tonemap << "\n";
  // Written only when not the default, so diffusion files stay as they were.
  if (info.objective == Objective::Regression) out << "objective=regression\n";
  out << "prediction=" << predictionName(info.prediction) << "\n"
      << "schedule=" << scheduleKindName(info.schedule) << "\n"
      << "schedule_steps=" << info.schedule_steps << "\n"
      << "respacing=" << info.respacing << "\n";
  notesToText(info, out);
  return out.str();
}

ModelInfo modelInfoFromText(const std::string& text, const std::string& source) {
  KeyValues kv(text, source);
  ModelInfo info;
  if (kv.has("base")) {
    if (kv.text("base") != "oidn") kv.fail("unknown base '" + kv.text("base") + "'");
    oidnInfoFromText(kv, info);
  } else {
    diffusionInfoFromText(kv, info);
  }
  for (const auto& [key, value] : kv.all())
    if (key.rfind("note.", 0) == 0) info.notes[key.substr(5)] = value;
  return info;
}

std::shared_ptr<ConditionalDenoiser> buildDenoiser(const ModelInfo& info) {
  if (info.base_kind != BaseKind::DiffusionUNet)
    throw std::invalid_argument("not a diffusion model (base=oidn)");
  auto base = std::make_shared<UNet>(info.base);
  if (info.has_control) return std::make_shared<ControlledDenoiser>(base, info.control);
  return std::make_shared<PriorDenoiser>(base);
}

std::shared_ptr<DenoisingPrior> LoadedModel::prior() const {
  if (auto controlled = std::dynamic_pointer_cast<ControlledDenoiser>(model))
    return controlled->base();
  if (auto plain = std::dynamic_pointer_cast<PriorDenoiser>(model)) return plain->prior();
  return nullptr;
}

void writeArchiveFile(const std::string& path, const std::string& kind, const std::string& text,
                      torch::serialize::OutputArchive& archive) {
  std::ostringstream archive_stream;
  archive.save_to(archive_stream);
  const std::string payload = archive_stream.str();
  writeAtomically(path, [&](std::ostream& out) {
    out << kMagic << "\n"
        << "kind " << kind << "\n"
        << "version " << kModelFormatVersion << "\n"
        << "text_bytes " << text.size() << "\n"
        << "archive_bytes " << payload.size() << "\n"
        << "checksum " << hex64(fnv1a64(text, payload)) << "\n"
        << text << payload;
  });
}

std::string archiveKind(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string magic, key, kind;
  if (!in || !std::getline(in, magic) || magic != kMagic || !(in >> key >> kind) || key != "kind")
    throw ModelError(path + ": not a model file (unknown header)");
  return kind;
}

ArchiveFile readArchiveFile(const std::string& path, const std::string& kind) {
  const MappedFile mapped(path);
  const std::string_view data = mapped.bytes();
  size_t pos = 0;
  std::string line, file_kind, version_text, text_size_text, archive_size_text, checksum;
  if (!headerLine(data, pos, line) || line != kMagic)
    throw ModelError(path + ": not a " + kind + " file (unknown header)");
  if (!headerValue(data, pos, "kind", file_kind))
    throw ModelError(path + ": damaged header (no kind)");
  if (file_kind != kind) throw ModelError(path + ": holds a " + file_kind + ", expected a " + kind);
  uint64_t version = 0, text_bytes = 0, archive_bytes = 0;
  if (!headerValue(data, pos, "version", version_text) || !parseSize(version_text, version))
    throw ModelError(path + ": damaged header (no version)");
  if (version < 1 || version > uint64_t(kModelFormatVersion))
    throw ModelError(path + ": format version " + version_text +
                     " is not supported (this build reads 1.." +
                     std::to_string(kModelFormatVersion) + ")");
  if (!headerValue(data, pos, "text_bytes", text_size_text) ||
      !parseSize(text_size_text, text_bytes) ||
      !headerValue(data, pos, "archive_bytes", archive_size_text) ||
      !parseSize(archive_size_text, archive_bytes) || !headerValue(data, pos, "checksum", checksum))
    throw ModelError(path + ": damaged header");
  const uint64_t available = data.size() - pos;
  if (text_bytes > available || archive_bytes > available - text_bytes)
    throw ModelError(path + ": truncated (" + std::to_string(available) + " of " +
                     std::to_string(text_bytes + archive_bytes) + " data bytes present)");
  if (text_bytes + archive_bytes != available)
    throw ModelError(path + ": " + std::to_string(available - text_bytes - archive_bytes) +
                     " unexpected bytes after the data");
  ArchiveFile file;
  file.version = static_cast<int>(version);
  file.text = data.substr(pos, text_bytes);
  const std::string_view payload = data.substr(pos + text_bytes, archive_bytes);
  if (hex64(fnv1a64(file.text, payload)) != checksum)
    throw ModelError(path + ": checksum mismatch (the file is corrupt)");
  try {
    file.archive.load_from(payload.data(), payload.size());
  } catch (const std::exception&) {
    throw ModelError(path + ": unreadable tensor archive");
  }
  return file;
}

void loadModuleWeights(torch::nn::Module& module, torch::serialize::InputArchive& archive,
                       const std::string& source) {
  std::map<std::string, std::vector<int64_t>> expected;
  for (const auto& item : module.named_parameters())
    expected[item.key()] = item.value().sizes().vec();
  for (const auto& item : module.named_buffers()) expected[item.key()] = item.value().sizes().vec();
  try {
    module.load(archive);
  } catch (const c10::Error& error) {
    const std::string what = error.what_without_backtrace();
    throw ModelError(source + ": weights do not match the model (" +
                     what.substr(0, what.find('\n')) + ")");
  }
  auto check = [&](const torch::OrderedDict<std::string, torch::Tensor>& tensors) {
    for (const auto& item : tensors)
      if (item.value().sizes().vec() != expected[item.key()])
        throw ModelError(source + ": weight '" + item.key() + "' has the wrong shape");
  };
  check(module.named_parameters());
  check(module.named_buffers());
}

void saveModelFile(const std::string& path, const ModelInfo& info, const torch::nn::Module& model) {
  torch::serialize::OutputArchive archive;
  model.save(archive);
  writeArchiveFile(path, "model", modelInfoToText(info), archive);
}

LoadedModel loadModelFile(const std::string& path) {
  auto file = readArchiveFile(path, "model");
  LoadedModel loaded;
  loaded.info = modelInfoFromText(file.text, path);
  if (loaded.info.base_kind == BaseKind::Oidn) {
    // Uninitialised: loadModuleWeights replaces every weight or throws.
    loaded.oidn = OidnBase(loaded.info.oidn.arch, loaded.info.oidn.input_sets, false);
    if (loaded.info.has_control) {
      loaded.oidnControlled = OidnControlled(loaded.oidn, loaded.info.oidn.control);
      loadModuleWeights(*loaded.oidnControlled, file.archive, path);
      loaded.oidnControlled->eval();
      return loaded;
    }
    loadModuleWeights(*loaded.oidn, file.archive, path);
    loaded.oidn->eval();
    return loaded;
  }
  loaded.model = buildDenoiser(loaded.info);
  loadModuleWeights(*loaded.model, file.archive, path);
  loaded.model->eval();
  return loaded;
}

}  // namespace dn
