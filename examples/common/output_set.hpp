// examples/common/output_set.hpp — write a set of .npy outputs all-or-nothing.
//
// docs/interop.md: on failure nothing is written. Outputs are staged in memory, written to
// temporary names in the output folder and renamed into place only when every write succeeded;
// on any failure the temporaries are removed and the error propagates.
#pragma once

#include <cstdint>
#include <filesystem>
#include <functional>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include "npy.hpp"

namespace cli {

class OutputSet {
 public:
  template <class T>
  void add(const std::string& file, std::vector<T> data, std::vector<std::int64_t> shape) {
    items_.push_back({file, [data = std::move(data), shape = std::move(shape)](const std::string& p) {
                        npy::write(p, data, shape);
                      }});
  }

  // Creates `dir` if needed and writes every staged file into it. Throws npy::Error or
  // std::filesystem::filesystem_error; then nothing new is left in `dir`.
  void commit(const std::filesystem::path& dir) const {
    namespace fs = std::filesystem;
    const bool created = !fs::exists(dir);
    fs::create_directories(dir);
    if (!fs::is_directory(dir)) throw npy::Error(dir.string() + ": not a directory");
    std::vector<fs::path> temps;
    try {
      for (const auto& it : items_) {
        const fs::path tmp = dir / ("." + it.file + ".partial");
        temps.push_back(tmp);
        it.write(tmp.string());
      }
      for (std::size_t k = 0; k < items_.size(); ++k) fs::rename(temps[k], dir / items_[k].file);
    } catch (...) {
      std::error_code ec;
      for (const auto& t : temps) fs::remove(t, ec);
      if (created) fs::remove(dir, ec);  // removes only an (empty) folder we created
      throw;
    }
  }

  std::size_t size() const { return items_.size(); }

 private:
  struct Item {
    std::string file;
    std::function<void(const std::string&)> write;
  };
  std::vector<Item> items_;
};

}  // namespace cli
