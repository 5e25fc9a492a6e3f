// atomic_file.h: outputs appear whole or not at all.
//
// AtomicOutput reserves a temporary file beside the target (same directory, so rename is atomic),
// the caller writes to tempPath(), and commit() renames it over the target. If the object dies
// without commit() (an exception, an error exit), the temporary is removed. A SIGKILL can leave a
// hidden ".NAME.canopy-tmp.*" file behind, never a half-written target.
#pragma once
#include <string>
#include <vector>

namespace canopy {

class AtomicOutput {
 public:
  // Creates the temporary file now, so an unwritable destination fails before any work is done.
  // Throws canopy::Error(Io) naming the path.
  explicit AtomicOutput(std::string target);
  ~AtomicOutput();
  AtomicOutput(const AtomicOutput&) = delete;
  AtomicOutput& operator=(const AtomicOutput&) = delete;

  const std::string& tempPath() const { return temp_; }
  const std::string& target() const { return target_; }
  // fsyncs and renames the temporary onto the target. Throws canopy::Error(Io) on failure.
  void commit();

 private:
  std::string target_, temp_;
  bool committed_ = false;
};

// Writes bytes to path atomically.
void writeFileAtomic(const std::string& path, const void* data, size_t size);
inline void writeFileAtomic(const std::string& path, const std::string& bytes) {
  writeFileAtomic(path, bytes.data(), bytes.size());
}
// Throws canopy::Error(Io) naming the path unless it is an existing, readable regular file.
void requireReadableFile(const std::string& path);
// Reads a whole file; throws canopy::Error(Io) naming the path (missing, directory, unreadable).
std::vector<unsigned char> readFile(const std::string& path);

}  // namespace canopy
