// atomic_file.h: outputs appear whole or not at all.
//
// AtomicOutput reserves a temporary file beside the target (same directory, so rename is atomic),
// the caller writes to tempPath(), and commit() renames it over the target. If the object dies
// without commit() (an exception, an error exit), the temporary is removed; so is it when the
// process is stopped by SIGINT, SIGTERM or SIGHUP (a handler unlinks every live temporary, then
// lets the signal take its default course). Only a SIGKILL can leave a hidden
// ".NAME.canopy-tmp.*" file behind, never a half-written target.
//
// Targets that are not regular files: a symbolic link is followed (the file it names is replaced,
// the link stays); a character device or FIFO (/dev/null, /dev/stdout, a pipe) is written through
// at commit() from a temporary in $TMPDIR (never replaced by a file); anything else is refused.
//
// Inside a tool's run (InputTracking, set by canopy::Tool), the files read through
// requireReadableFile/readFile/noteInput are remembered, and an output whose target is one of them
// is refused (usage error) instead of replacing the input; so is a second output to the same
// file in the same run (once one of them is committed; an AtomicOutput that is never committed,
// e.g. an early writability check, does not count).
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
  // fsyncs and renames the temporary onto the target (or copies it into a device or FIFO).
  // Throws canopy::Error(Io) on failure, canopy::Error(Usage) if the target is an input.
  void commit();

 private:
  std::string target_;      // as given (messages)
  std::string final_;       // where the bytes go: the target with symbolic links followed
  std::string temp_;
  std::string key_;            // final_'s real directory + name (tool runs only), claimed at commit
  bool writeThrough_ = false;  // final_ is a character device or FIFO: copied into, not replaced
  int registered_ = -1;        // slot in the signal handler's list of temporaries
  bool committed_ = false;
};

// Writes bytes to path atomically.
void writeFileAtomic(const std::string& path, const void* data, size_t size);
inline void writeFileAtomic(const std::string& path, const std::string& bytes) {
  writeFileAtomic(path, bytes.data(), bytes.size());
}
// Throws canopy::Error(Io) naming the path unless it is an existing, readable regular file.
// Notes the file as an input of the current run (see InputTracking).
void requireReadableFile(const std::string& path);
// Notes an existing file as an input of the current run (for readers that open files themselves).
void noteInput(const std::string& path);

// While alive (one per tool run: canopy::Tool::run), inputs and outputs are tracked as above.
class InputTracking {
 public:
  InputTracking();
  ~InputTracking();
  InputTracking(const InputTracking&) = delete;
  InputTracking& operator=(const InputTracking&) = delete;
};
// Reads a whole file; throws canopy::Error(Io) naming the path (missing, directory, unreadable).
std::vector<unsigned char> readFile(const std::string& path);

}  // namespace canopy
