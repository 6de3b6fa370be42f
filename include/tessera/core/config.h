#pragma once
// YAML configuration with strict keys. Each stage owns a Config struct whose member
// initialisers are the only defaults; a `readConfig(ConfigSection&, XConfig&)` function next to
// it overwrites the members present in the file. After every stage has read its section,
// ConfigDocument::checkAllKeysUsed() rejects any key nobody read (a typo, a removed option),
// naming the key and the file, as cartographer's "every key used exactly once" check does.
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

namespace tessera::core {

class ConfigDocument;

// A map inside a config document, e.g. the `fusion:` block. Cheap to copy.
// Not thread-safe; configuration is read once, before the pipeline starts.
class ConfigSection {
 public:
  // Each overload leaves `value` unchanged when the key is absent and throws ConfigError
  // (naming the file, the key and the expected type) when the value has the wrong type.
  void read(std::string_view key, double& value) const;
  void read(std::string_view key, int& value) const;
  void read(std::string_view key, bool& value) const;
  void read(std::string_view key, std::string& value) const;
  // A list of numbers, e.g. `position: [1.0, 2.0, 0.5]`.
  void read(std::string_view key, std::vector<double>& value) const;
  void read(std::string_view key, std::vector<int>& value) const;
  // A list of lists of numbers, e.g. a polygon `[[0, 0], [4, 0], [4, 2.6]]`.
  void read(std::string_view key, std::vector<std::vector<double>>& value) const;

  bool has(std::string_view key) const;

  // This section as YAML text (to record a definition verbatim, e.g. in ground truth).
  std::string toYaml() const;

  // The sub-map under `key` (empty when absent).
  ConfigSection section(std::string_view key) const;
  // The maps of a list under `key` (empty when absent), addressed as key[i] in messages.
  std::vector<ConfigSection> list(std::string_view key) const;
  // Dotted path of this section, for messages ("" at the root).
  const std::string& path() const { return path_; }
  // The origin (file name) of the document, for messages.
  const std::string& origin() const;

  struct State;  // the parsed document and the keys read so far (defined in config.cpp)

 private:
  friend class ConfigDocument;
  ConfigSection(std::shared_ptr<State> document, std::string path);
  std::shared_ptr<State> document_;
  std::string path_;  // dotted key path of this section, "" for the root
};

class ConfigDocument {
 public:
  // Parses `path`; throws ConfigError when it is missing or not valid YAML.
  static ConfigDocument load(const std::filesystem::path& path);
  // A document with no keys: every Config keeps its defaults.
  static ConfigDocument empty();
  // Parses YAML text; `origin` names it in error messages.
  static ConfigDocument fromString(const std::string& yaml, const std::string& origin);

  ConfigSection root() const;
  const std::string& origin() const;

  // Throws ConfigError naming every key in the file that no read() or section() consumed.
  void checkAllKeysUsed() const;
  // Dotted paths of keys that were asked for but are not in the file (used to check that
  // config/default.yaml documents every key).
  std::vector<std::string> keysAskedButAbsent() const;

 private:
  explicit ConfigDocument(std::shared_ptr<ConfigSection::State> state);
  std::shared_ptr<ConfigSection::State> state_;
};

}  // namespace tessera::core
