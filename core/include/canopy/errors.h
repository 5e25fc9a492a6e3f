// errors.h: the exit-code table shared by every Canopy tool, and the typed error that carries it.
//
// Library code throws canopy::Error (never calls exit()); only a tool's main turns it into a
// message on stderr and an exit code. The table is documented once, in README.md:
//   0 ok, 1 usage, 2 I/O, 3 invalid input, 4 runtime failure, 5 unsupported.
#pragma once
#include <cstdio>
#include <stdexcept>
#include <string>

namespace canopy {

enum class ExitCode : int {
  Ok = 0,
  Usage = 1,        // bad command line
  Io = 2,           // a file could not be read or written
  InvalidInput = 3, // a file was read but its content is wrong (corrupt, NaN, empty mesh...)
  Runtime = 4,      // a failure while running (out of memory, CUDA error)
  Unsupported = 5,  // asked for something this build or file does not support
};

class Error : public std::runtime_error {
 public:
  Error(ExitCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ExitCode code() const { return code_; }

 private:
  ExitCode code_;
};

// Shorthands: the message should name the file and the problem in one line.
inline Error usageError(const std::string& m) { return Error(ExitCode::Usage, m); }
inline Error ioError(const std::string& m) { return Error(ExitCode::Io, m); }
inline Error invalidInput(const std::string& m) { return Error(ExitCode::InvalidInput, m); }
inline Error runtimeError(const std::string& m) { return Error(ExitCode::Runtime, m); }
inline Error unsupported(const std::string& m) { return Error(ExitCode::Unsupported, m); }

// A value in a message: %g (1e-09, 0.05, 1e+30), not std::to_string's %f (0.000000).
inline std::string formatNumber(double v) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", v);
  return b;
}

}  // namespace canopy
