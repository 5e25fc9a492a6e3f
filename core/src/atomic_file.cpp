// atomic_file.cpp: temporary file + rename, and whole-file reads with clear errors.
#include "canopy/atomic_file.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstring>
#include <fstream>

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

}  // namespace

AtomicOutput::AtomicOutput(std::string target) : target_(std::move(target)) {
  if (target_.empty()) throw usageError("empty output path");
  std::string dir, base;
  splitPath(target_, dir, base);
  if (base.empty()) throw usageError(target_ + ": output path names a directory");
  struct stat st;
  if (stat(target_.c_str(), &st) == 0 && S_ISDIR(st.st_mode))
    throw ioError(target_ + ": output path is a directory");
  std::string templ = (dir == "/" ? "" : dir) + "/." + base + ".canopy-tmp.XXXXXX";
  std::vector<char> buf(templ.begin(), templ.end());
  buf.push_back('\0');
  int fd = mkstemp(buf.data());
  if (fd < 0) throw ioError(target_ + ": cannot write output (" + errnoText() + ")");
  close(fd);
  temp_ = buf.data();
}

AtomicOutput::~AtomicOutput() {
  if (!committed_ && !temp_.empty()) std::remove(temp_.c_str());
}

void AtomicOutput::commit() {
  int fd = open(temp_.c_str(), O_RDONLY);
  if (fd >= 0) {
    fsync(fd);
    close(fd);
  }
  // mkstemp creates 0600; outputs are ordinary files (0644 less the umask).
  mode_t mask = umask(0);
  umask(mask);
  chmod(temp_.c_str(), 0666 & ~mask);
  if (std::rename(temp_.c_str(), target_.c_str()) != 0)
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
