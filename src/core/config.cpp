#include "tessera/core/config.h"

#include <cmath>
#include <optional>
#include <set>

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include "tessera/core/error.h"

namespace tessera::core {

struct ConfigSection::State {
  YAML::Node root;
  std::string origin;
  std::set<std::string> used;    // dotted paths consumed by read() or section()
  std::set<std::string> absent;  // dotted paths asked for but not present
};

namespace {

std::string joinPath(const std::string& parent, std::string_view key) {
  return parent.empty() ? std::string(key) : parent + "." + std::string(key);
}

// Walks the dotted path ("planes[2].texture") from `node`; returns an undefined node when any
// part is missing. (Recursive on purpose: assigning yaml-cpp nodes would rewrite the tree.)
YAML::Node lookup(const YAML::Node& node, std::string_view path) {
  if (path.empty()) return node;
  const std::size_t dot = path.find('.');
  std::string_view part = path.substr(0, dot);
  const std::size_t bracket = part.find('[');
  if (!node.IsMap()) return YAML::Node(YAML::NodeType::Undefined);
  YAML::Node child = node[std::string(part.substr(0, bracket))];
  if (!child) return YAML::Node(YAML::NodeType::Undefined);
  if (bracket != std::string_view::npos) {
    const std::size_t index = std::stoul(std::string(part.substr(bracket + 1)));
    if (!child.IsSequence() || index >= child.size()) return YAML::Node(YAML::NodeType::Undefined);
    const YAML::Node item = child[index];
    child.reset(item);
  }
  return dot == std::string_view::npos ? child : lookup(child, path.substr(dot + 1));
}

std::vector<double> numbersOf(const YAML::Node& node, const std::string& origin,
                              const std::string& path) {
  std::vector<double> values;
  if (!node.IsSequence()) {
    throw ConfigError(fmt::format("{}: key '{}' must be a list of numbers", origin, path));
  }
  for (const auto& item : node) {
    try {
      values.push_back(item.as<double>());
    } catch (const YAML::Exception&) {
      throw ConfigError(fmt::format("{}: key '{}' must be a list of numbers", origin, path));
    }
  }
  return values;
}

// The node at `path`, remembered as used; nothing (and remembered as absent) when missing.
std::optional<YAML::Node> presentNode(ConfigSection::State& state, const std::string& path) {
  const YAML::Node node = lookup(state.root, path);
  if (!node.IsDefined() || node.IsNull()) {
    state.absent.insert(path);
    return std::nullopt;
  }
  state.used.insert(path);
  return node;
}

template <typename T>
void readScalar(ConfigSection::State& state, const std::string& path, T& value,
                const char* type_name) {
  const auto present = presentNode(state, path);
  if (!present) return;
  const YAML::Node& node = *present;
  if (!node.IsScalar()) {
    throw ConfigError(fmt::format("{}: key '{}' must be {}", state.origin, path, type_name));
  }
  try {
    value = node.as<T>();
  } catch (const YAML::Exception&) {
    throw ConfigError(fmt::format("{}: key '{}' must be {}, got '{}'", state.origin, path,
                                  type_name, node.Scalar()));
  }
}

// A map's keys nobody read; maps and lists of maps that were opened are searched inside.
void collectUnused(const YAML::Node& node, const std::string& path,
                   const std::set<std::string>& used, std::vector<std::string>& unused) {
  if (!node.IsMap()) return;
  for (const auto& entry : node) {
    const std::string child = joinPath(path, entry.first.as<std::string>());
    if (!used.contains(child)) {
      unused.push_back(child);
    } else if (entry.second.IsMap()) {
      collectUnused(entry.second, child, used, unused);
    } else if (entry.second.IsSequence() && used.contains(child + "[]")) {
      for (std::size_t i = 0; i < entry.second.size(); ++i) {
        collectUnused(entry.second[i], fmt::format("{}[{}]", child, i), used, unused);
      }
    }
  }
}

}  // namespace

ConfigSection::ConfigSection(std::shared_ptr<State> document, std::string path)
    : document_(std::move(document)), path_(std::move(path)) {}

void ConfigSection::read(std::string_view key, double& value) const {
  readScalar(*document_, joinPath(path_, key), value, "a number");
}
void ConfigSection::read(std::string_view key, int& value) const {
  readScalar(*document_, joinPath(path_, key), value, "an integer");
}
void ConfigSection::read(std::string_view key, bool& value) const {
  readScalar(*document_, joinPath(path_, key), value, "true or false");
}
void ConfigSection::read(std::string_view key, std::string& value) const {
  readScalar(*document_, joinPath(path_, key), value, "a string");
}

void ConfigSection::read(std::string_view key, std::vector<double>& value) const {
  const std::string path = joinPath(path_, key);
  if (const auto node = presentNode(*document_, path)) {
    value = numbersOf(*node, document_->origin, path);
  }
}

void ConfigSection::read(std::string_view key, std::vector<int>& value) const {
  const std::string path = joinPath(path_, key);
  const auto node = presentNode(*document_, path);
  if (!node) return;
  std::vector<int> integers;
  for (const double number : numbersOf(*node, document_->origin, path)) {
    if (number != std::floor(number)) {
      throw ConfigError(
          fmt::format("{}: key '{}' must be a list of integers", document_->origin, path));
    }
    integers.push_back(static_cast<int>(number));
  }
  value = std::move(integers);
}

void ConfigSection::read(std::string_view key, std::vector<std::vector<double>>& value) const {
  const std::string path = joinPath(path_, key);
  const auto node = presentNode(*document_, path);
  if (!node) return;
  if (!node->IsSequence()) {
    throw ConfigError(
        fmt::format("{}: key '{}' must be a list of lists of numbers", document_->origin, path));
  }
  value.clear();
  for (const auto& row : *node) value.push_back(numbersOf(row, document_->origin, path));
}

bool ConfigSection::has(std::string_view key) const {
  const YAML::Node node = lookup(document_->root, joinPath(path_, key));
  return node.IsDefined() && !node.IsNull();
}

const std::string& ConfigSection::origin() const { return document_->origin; }

std::string ConfigSection::toYaml() const {
  const YAML::Node node = path_.empty() ? document_->root : lookup(document_->root, path_);
  YAML::Emitter out;
  out << YAML::Flow << node;
  return out.c_str();
}

std::vector<ConfigSection> ConfigSection::list(std::string_view key) const {
  const std::string path = joinPath(path_, key);
  const YAML::Node node = lookup(document_->root, path);
  std::vector<ConfigSection> items;
  if (!node.IsDefined() || node.IsNull()) return items;
  if (!node.IsSequence()) {
    throw ConfigError(fmt::format("{}: key '{}' must be a list", document_->origin, path));
  }
  document_->used.insert(path);
  document_->used.insert(path + "[]");  // its items are checked for unknown keys too
  for (std::size_t i = 0; i < node.size(); ++i) {
    if (!node[i].IsMap()) {
      throw ConfigError(
          fmt::format("{}: item {} of '{}' must be a map of settings", document_->origin, i, path));
    }
    const std::string item_path = fmt::format("{}[{}]", path, i);
    document_->used.insert(item_path);
    items.push_back(ConfigSection(document_, item_path));
  }
  return items;
}

ConfigSection ConfigSection::section(std::string_view key) const {
  const std::string path = joinPath(path_, key);
  const YAML::Node node = lookup(document_->root, path);
  if (node.IsDefined() && !node.IsNull()) {
    if (!node.IsMap()) {
      throw ConfigError(
          fmt::format("{}: key '{}' must be a map of settings", document_->origin, path));
    }
    document_->used.insert(path);
  }
  return ConfigSection(document_, path);
}

ConfigDocument::ConfigDocument(std::shared_ptr<ConfigSection::State> state)
    : state_(std::move(state)) {}

ConfigDocument ConfigDocument::fromString(const std::string& yaml, const std::string& origin) {
  auto state = std::make_shared<ConfigSection::State>();
  state->origin = origin;
  try {
    state->root = YAML::Load(yaml);
  } catch (const YAML::Exception& e) {
    throw ConfigError(fmt::format("{}: not valid YAML: {}", origin, e.what()));
  }
  if (state->root.IsDefined() && !state->root.IsNull() && !state->root.IsMap()) {
    throw ConfigError(fmt::format("{}: the top level must be a map of sections", origin));
  }
  return ConfigDocument(std::move(state));
}

ConfigDocument ConfigDocument::load(const std::filesystem::path& path) {
  auto state = std::make_shared<ConfigSection::State>();
  state->origin = path.string();
  std::error_code ec;
  if (!std::filesystem::is_regular_file(path, ec)) {
    throw ConfigError(fmt::format("{}: config file not found", path.string()));
  }
  try {
    state->root = YAML::LoadFile(path.string());
  } catch (const YAML::Exception& e) {
    throw ConfigError(fmt::format("{}: not valid YAML: {}", path.string(), e.what()));
  }
  if (state->root.IsDefined() && !state->root.IsNull() && !state->root.IsMap()) {
    throw ConfigError(fmt::format("{}: the top level must be a map of sections", path.string()));
  }
  return ConfigDocument(std::move(state));
}

ConfigDocument ConfigDocument::empty() { return fromString("{}", "(defaults)"); }

ConfigSection ConfigDocument::root() const { return ConfigSection(state_, ""); }

const std::string& ConfigDocument::origin() const { return state_->origin; }

void ConfigDocument::checkAllKeysUsed() const {
  std::vector<std::string> unused;
  collectUnused(state_->root, "", state_->used, unused);
  if (unused.empty()) return;
  throw ConfigError(
      fmt::format("{}: unknown key{} '{}' (misspelled, or not a tessera setting; "
                  "config/default.yaml lists every key)",
                  state_->origin, unused.size() > 1 ? "s" : "", fmt::join(unused, "', '")));
}

std::vector<std::string> ConfigDocument::keysAskedButAbsent() const {
  return {state_->absent.begin(), state_->absent.end()};
}

}  // namespace tessera::core
