// atomic_file.cpp: temporary file + rename, and whole-file reads with clear errors.
#include "canopy/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <csignal>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <mutex>
#include <set>
#include <utility>

#include "canopy/errors.h"

namespace canopy {
namespace {

std::string errnoText() { return std::strerror(errno); }

void splitPath(const std::string& p, std::string& dir, std::string& base) {
  auto slash = p.find_last_of('/');
  if (slash == std::string::npos) {
    dir = ".";
    base = p;
  } else {
    dir = slash == 0 ? "/" : p.substr(0, slash);
    base = p.substr(slash + 1);
  }
}

// The path with symbolic links followed (the last component's, repeatedly; a dangling link gives
// the path it names, which the output then creates).
std::string followLinks(const std::string& target) {
  std::string p = target;
  for (int hops = 0; hops < 40; ++hops) {
    struct stat st;
    if (lstat(p.c_str(), &st) != 0 || !S_ISLNK(st.st_mode)) return p;
    std::vector<char> buf(size_t(st.st_size > 0 ? st.st_size : 255) + 2);
    const ssize_t n = readlink(p.c_str(), buf.data(), buf.size() - 1);
    if (n < 0) throw ioError(target + ": cannot read symbolic link (" + errnoText() + ")");
    std::string link(buf.data(), size_t(n));
    if (link.empty()) throw ioError(target + ": empty symbolic link");
    if (link[0] != '/') {
      std::string dir, base;
      splitPath(p, dir, base);
      link = dir + "/" + link;
    }
    p = link;
  }
  throw ioError(target + ": too many levels of symbolic links");
}

// Inputs and outputs of the current tool run (InputTracking).
std::mutex gTrackMutex;
int gTrackDepth = 0;
std::set<std::pair<dev_t, ino_t>> gInputs;
std::set<std::string> gOutputs;  // committed outputs: real directory + name

void noteInputStat(const struct stat& st) {
  std::lock_guard<std::mutex> lock(gTrackMutex);
  if (gTrackDepth > 0) gInputs.insert({st.st_dev, st.st_ino});
}

bool isTrackedInput(const struct stat& st) {
  std::lock_guard<std::mutex> lock(gTrackMutex);
  return gTrackDepth > 0 && gInputs.count({st.st_dev, st.st_ino}) != 0;
}

// A committed output of the run: a second output to the same file is refused (a reservation
// that is never committed, e.g. an early writability check, does not count).
void claimOutput(const std::string& key, const std::string& target) {
  if (key.empty()) return;
  std::lock_guard<std::mutex> lock(gTrackMutex);
  if (gTrackDepth > 0 && !gOutputs.insert(key).second) throw usageError(target + ": the same file is given for two outputs");
}

Error sameFileAsInput(const std::string& target) {
  return usageError(target + ": output path is the same file as an input (not overwritten)");
}

void refuseInput(const std::string& finalPath, const std::string& target) {
  struct stat st;
  if (stat(finalPath.c_str(), &st) == 0 && isTrackedInput(st)) throw sameFileAsInput(target);
}

// Temporaries that SIGINT, SIGTERM and SIGHUP remove: fixed slots, so that the handler only reads
// plain memory and calls unlink (async-signal-safe).
constexpr int kTempSlots = 64;
constexpr size_t kTempPathMax = 4096;
char gTempPath[kTempSlots][kTempPathMax];
std::atomic<int> gTempState[kTempSlots];  // 0 free, 1 being filled, 2 live
static_assert(std::atomic<int>::is_always_lock_free, "the signal handler reads the slots' states");

extern "C" void removeTemporariesAndDie(int sig) {
  for (int i = 0; i < kTempSlots; ++i)
    if (gTempState[i].load(std::memory_order_acquire) == 2) unlink(gTempPath[i]);
  raise(sig);  // SA_RESETHAND restored the default action: it runs when the handler returns
}

void installSignalCleanup() {
  static std::once_flag once;
  std::call_once(once, [] {
    for (int sig : {SIGINT, SIGTERM, SIGHUP}) {
      struct sigaction old {};
      if (sigaction(sig, nullptr, &old) != 0 || old.sa_handler != SIG_DFL) continue;  // ignored or handled: left alone
      struct sigaction sa {};
      sa.sa_handler = removeTemporariesAndDie;
      sigemptyset(&sa.sa_mask);
      sa.sa_flags = SA_RESETHAND;
      sigaction(sig, &sa, nullptr);
    }
  });
}

int registerTemporary(const std::string& path) {
  if (path.size() >= kTempPathMax) return -1;
  installSignalCleanup();
  for (int i = 0; i < kTempSlots; ++i) {
    int expected = 0;
    if (gTempState[i].compare_exchange_strong(expected, 1)) {
      std::memcpy(gTempPath[i], path.c_str(), path.size() + 1);
      gTempState[i].store(2, std::memory_order_release);
      return i;
    }
  }
  return -1;  // more than 64 at once: this one is not removed on a signal
}

void unregisterTemporary(int slot) {
  if (slot >= 0) gTempState[slot].store(0, std::memory_order_release);
}

}  // namespace

InputTracking::InputTracking() {
  std::lock_guard<std::mutex> lock(gTrackMutex);
  if (gTrackDepth++ == 0) gInputs.clear(), gOutputs.clear();
}

InputTracking::~InputTracking() {
  std::lock_guard<std::mutex> lock(gTrackMutex);
  if (--gTrackDepth == 0) gInputs.clear(), gOutputs.clear();
}

void noteInput(const std::string& path) {
  struct stat st;
  if (stat(path.c_str(), &st) == 0) noteInputStat(st);
}

AtomicOutput::AtomicOutput(std::string target) : target_(std::move(target)) {
  if (target_.empty()) throw usageError("empty output path");
  std::string dir, base;
  splitPath(target_, dir, base);
  if (base.empty()) throw usageError(target_ + ": output path names a directory");
  final_ = followLinks(target_);
  splitPath(final_, dir, base);
  struct stat st;
  if (stat(final_.c_str(), &st) == 0) {
    if (S_ISDIR(st.st_mode)) throw ioError(target_ + ": output path is a directory");
    writeThrough_ = S_ISCHR(st.st_mode) || S_ISFIFO(st.st_mode);
    if (!writeThrough_ && !S_ISREG(st.st_mode))
      throw ioError(target_ + ": output path is not a regular file, a character device or a FIFO");
    if (isTrackedInput(st)) throw sameFileAsInput(target_);
  }
  if (!writeThrough_) {
    char* real = realpath(dir.c_str(), nullptr);
    if (real) {
      const std::string key = std::string(real) + "/" + base;
      std::free(real);
      std::lock_guard<std::mutex> lock(gTrackMutex);
      if (gTrackDepth > 0) {
        if (gOutputs.count(key) != 0) throw usageError(target_ + ": the same file is given for two outputs");
        key_ = key;
      }
    }
  }
  std::string templ;
  if (writeThrough_) {
    const char* tmp = std::getenv("TMPDIR");
    templ = std::string(tmp && *tmp ? tmp : "/tmp") + "/canopy-out.XXXXXX";
  } else {
    templ = (dir == "/" ? "" : dir) + "/." + base + ".canopy-tmp.XXXXXX";
  }
  std::vector<char> buf(templ.begin(), templ.end());
  buf.push_back('\0');
  int fd = mkstemp(buf.data());
  if (fd < 0) throw ioError(target_ + ": cannot write output (" + errnoText() + ")");
  close(fd);
  temp_ = buf.data();
  registered_ = registerTemporary(temp_);
}

AtomicOutput::~AtomicOutput() {
  if (!committed_ && !temp_.empty()) std::remove(temp_.c_str());
  unregisterTemporary(registered_);
}

void AtomicOutput::commit() {
  refuseInput(final_, target_);  // an input read after the output was reserved
  claimOutput(key_, target_);
  if (writeThrough_) {
    int in = open(temp_.c_str(), O_RDONLY | O_CLOEXEC);
    int out = in < 0 ? -1 : open(final_.c_str(), O_WRONLY | O_CLOEXEC);
    if (in < 0 || out < 0) {
      const std::string why = errnoText();
      if (in >= 0) close(in);
      throw ioError(target_ + ": cannot write output (" + why + ")");
    }
    std::vector<char> chunk(size_t(1) << 20);
    for (;;) {
      const ssize_t n = read(in, chunk.data(), chunk.size());
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) break;
      for (ssize_t done = 0; done < n;) {
        const ssize_t w = write(out, chunk.data() + done, size_t(n - done));
        if (w < 0 && errno == EINTR) continue;
        if (w <= 0) {
          const std::string why = errnoText();
          close(in), close(out);
          throw ioError(target_ + ": write failed (" + why + ")");
        }
        done += w;
      }
    }
    close(in);
    if (close(out) != 0) throw ioError(target_ + ": write failed (" + errnoText() + ")");
    std::remove(temp_.c_str());
    committed_ = true;
    return;
  }
  int fd = open(temp_.c_str(), O_RDONLY);
  if (fd >= 0) {
    fsync(fd);
    close(fd);
  }
  // mkstemp creates 0600; outputs are ordinary files (0644 less the umask).
  mode_t mask = umask(0);
  umask(mask);
  chmod(temp_.c_str(), 0666 & ~mask);
  if (std::rename(temp_.c_str(), final_.c_str()) != 0)
    throw ioError(target_ + ": cannot rename temporary output into place (" + errnoText() + ")");
  committed_ = true;
}

void writeFileAtomic(const std::string& path, const void* data, size_t size) {
  AtomicOutput out(path);
  {
    std::ofstream f(out.tempPath(), std::ios::binary | std::ios::trunc);
    f.write(static_cast<const char*>(data), std::streamsize(size));
    f.flush();
    if (!f) throw ioError(path + ": write failed (disk full?)");
  }
  out.commit();
}

static struct stat statReadable(const std::string& path) {
  struct stat st;
  if (stat(path.c_str(), &st) != 0) throw ioError(path + ": cannot open (" + errnoText() + ")");
  if (S_ISDIR(st.st_mode)) throw ioError(path + ": is a directory, expected a file");
  if (access(path.c_str(), R_OK) != 0) throw ioError(path + ": cannot read (" + errnoText() + ")");
  noteInputStat(st);
  return st;
}

void requireReadableFile(const std::string& path) { statReadable(path); }

std::vector<unsigned char> readFile(const std::string& path) {
  struct stat st = statReadable(path);
  std::ifstream f(path, std::ios::binary);
  if (!f) throw ioError(path + ": cannot open for reading");
  std::vector<unsigned char> bytes(size_t(st.st_size));
  if (!bytes.empty()) f.read(reinterpret_cast<char*>(bytes.data()), std::streamsize(bytes.size()));
  if (!f) throw ioError(path + ": read failed");
  return bytes;
}

}  // namespace canopy
