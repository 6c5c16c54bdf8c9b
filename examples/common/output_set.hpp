// examples/common/output_set.hpp — write a set of .npy outputs all-or-nothing.
//
// docs/interop.md "Outputs": on failure OUT ends byte-for-byte as it was. The scheme:
//
//  * Outputs are staged in memory (add) and written only by commit(OUT).
//  * commit stages into a fresh, uniquely named directory made with mkdtemp (exclusive
//    creation; a planted file or symlink at that name makes mkdtemp pick another name, it is
//    never followed). The staging directory lives where the final moves stay on one
//    filesystem, so that every move is a rename(2):
//      - OUT exists: the staging directory is OUT/.smg_stage.XXXXXX; each output is renamed
//        from it onto OUT/<file> (atomic per file). A file it replaces is first hard-linked
//        into the staging directory as a backup; if a later move fails, the moves already
//        done are undone (backups renamed back, new files removed), so OUT ends as before.
//        An existing OUT/<file> that is not a regular file (a directory, a symlink, ...) is
//        an error, never replaced.
//      - OUT does not exist: missing parents are created (and remembered), the staging
//        directory is PARENT/.smg_stage.XXXXXX, the outputs are written into its
//        subdirectory "out" which is renamed to OUT in one rename(2): OUT appears complete
//        or not at all.
//  * Every file is created with open(O_CREAT | O_EXCL | O_NOFOLLOW).
//  * On any failure the staging directory and every folder the run created (parents
//    included, deepest first) are removed, and the error propagates.
//
// Test hook: the environment variable SMG_CLI_TEST_FAIL_MOVE=k (k >= 1) makes the k-th move into
// an existing OUT fail (k = 1: also the single move of a new OUT), so that the rollback can be tested without a full disk.
#pragma once

#include <cerrno>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <functional>
#include <string>
#include <system_error>
#include <utility>
#include <vector>

#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include "npy.hpp"

namespace cli {

class OutputSet {
 public:
  template <class T>
  void add(const std::string& file, std::vector<T> data, std::vector<std::int64_t> shape) {
    npy::detail::checked_count(shape, sizeof(T), file);
    items_.push_back({file, [data = std::move(data), shape = std::move(shape)](const std::string& p) {
                        if (static_cast<std::int64_t>(data.size()) !=
                            npy::detail::checked_count(shape, sizeof(T), p))
                          throw npy::Error(p + ": " + std::to_string(data.size()) + " values for shape " +
                                           npy::shape_string(shape));
                        npy::write_new(p, data.data(), shape);
                      }});
  }

  // Writes every staged file into `dir` (created with its parents if needed), all-or-nothing.
  // Throws npy::Error naming the path and the problem; then `dir` and the file system are as
  // they were before the call.
  void commit(const std::filesystem::path& dir_in) const {
    namespace fs = std::filesystem;
    fs::path dir = dir_in.lexically_normal();
    while (dir.has_parent_path() && dir.filename().empty() && dir != dir.root_path()) dir = dir.parent_path();  // "out/" -> "out"
    std::error_code ec;
    struct stat st {};
    const bool exists = ::lstat(dir.c_str(), &st) == 0;
    if (exists) {
      struct stat target {};
      if (::stat(dir.c_str(), &target) != 0 || !S_ISDIR(target.st_mode))
        throw npy::Error(dir.string() + ": not a directory");
      commit_into_existing(dir);
      return;
    }
    if (errno != ENOENT && errno != ENOTDIR) throw npy::Error(dir.string() + ": " + std::strerror(errno));
    // OUT does not exist: create its missing parents, remembering them for the cleanup.
    fs::path parent = dir.has_parent_path() ? dir.parent_path() : fs::path(".");
    if (parent.empty()) parent = ".";
    std::vector<fs::path> created;  // outermost first
    try {
      std::vector<fs::path> missing;
      for (fs::path p = parent; !p.empty(); p = p.parent_path()) {
        struct stat ps {};
        if (::lstat(p.c_str(), &ps) == 0) {
          struct stat pt {};
          if (::stat(p.c_str(), &pt) != 0 || !S_ISDIR(pt.st_mode))
            throw npy::Error(p.string() + ": not a directory");
          break;
        }
        missing.push_back(p);
        if (p == p.parent_path()) break;
      }
      for (auto it = missing.rbegin(); it != missing.rend(); ++it) {
        if (::mkdir(it->c_str(), 0777) != 0)
          throw npy::Error(it->string() + ": cannot create folder: " + std::strerror(errno));
        created.push_back(*it);
      }
      const fs::path stage = make_stage(parent, dir);
      try {
        const fs::path out = stage / "out";
        if (::mkdir(out.c_str(), 0777) != 0)
          throw npy::Error(out.string() + ": cannot create folder: " + std::strerror(errno));
        for (const auto& it : items_) it.write((out / it.file).string());
        if (fail_move_at() == 1)
          throw npy::Error(dir.string() + ": cannot move the outputs into place: injected failure (SMG_CLI_TEST_FAIL_MOVE)");
        if (::rename(out.c_str(), dir.c_str()) != 0)
          throw npy::Error(dir.string() + ": cannot move the outputs into place: " + std::strerror(errno));
      } catch (...) {
        fs::remove_all(stage, ec);
        throw;
      }
      fs::remove_all(stage, ec);
    } catch (...) {
      for (auto it = created.rbegin(); it != created.rend(); ++it) ::rmdir(it->c_str());
      throw;
    }
  }

  std::size_t size() const { return items_.size(); }

 private:
  struct Item {
    std::string file;
    std::function<void(const std::string&)> write;
  };

  static std::filesystem::path make_stage(const std::filesystem::path& where, const std::filesystem::path& dir) {
    std::string tmpl = (where / ".smg_stage.XXXXXX").string();
    if (::mkdtemp(tmpl.data()) == nullptr)
      throw npy::Error(dir.string() + ": cannot create a staging folder in " + where.string() + ": " +
                       std::strerror(errno));
    return tmpl;
  }

  static int fail_move_at() {
    const char* v = std::getenv("SMG_CLI_TEST_FAIL_MOVE");
    return v ? std::atoi(v) : 0;
  }

  void commit_into_existing(const std::filesystem::path& dir) const {
    namespace fs = std::filesystem;
    std::error_code ec;
    const fs::path stage = make_stage(dir, dir);
    struct Moved {
      fs::path target, backup;  // backup empty: there was no old file
    };
    std::vector<Moved> moved;
    try {
      for (std::size_t k = 0; k < items_.size(); ++k)
        items_[k].write((stage / ("new." + std::to_string(k))).string());
      const int fail_at = fail_move_at();
      for (std::size_t k = 0; k < items_.size(); ++k) {
        const fs::path target = dir / items_[k].file;
        fs::path backup;
        struct stat ts {};
        if (::lstat(target.c_str(), &ts) == 0) {
          if (!S_ISREG(ts.st_mode))
            throw npy::Error(target.string() + ": exists and is not a regular file (not replaced)");
          backup = stage / ("old." + std::to_string(k));
          if (::link(target.c_str(), backup.c_str()) != 0)
            throw npy::Error(target.string() + ": cannot keep a backup before replacing it: " +
                             std::strerror(errno));
        } else if (errno != ENOENT) {
          throw npy::Error(target.string() + ": " + std::strerror(errno));
        }
        const fs::path src = stage / ("new." + std::to_string(k));
        if (fail_at == static_cast<int>(k) + 1)
          throw npy::Error(target.string() + ": cannot move into place: injected failure (SMG_CLI_TEST_FAIL_MOVE)");
        if (::rename(src.c_str(), target.c_str()) != 0)
          throw npy::Error(target.string() + ": cannot move into place: " + std::strerror(errno));
        moved.push_back({target, backup});
      }
    } catch (...) {
      // Undo the moves already done, newest first: restore the old file or remove the new one.
      for (auto it = moved.rbegin(); it != moved.rend(); ++it) {
        if (!it->backup.empty())
          ::rename(it->backup.c_str(), it->target.c_str());
        else
          ::unlink(it->target.c_str());
      }
      fs::remove_all(stage, ec);
      throw;
    }
    fs::remove_all(stage, ec);
  }

  std::vector<Item> items_;
};

}  // namespace cli
