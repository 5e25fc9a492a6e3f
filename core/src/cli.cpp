// cli.cpp: the shared command-line layer (see cli.h).
#include "canopy/cli.h"

#include "canopy/atomic_file.h"

#include <unistd.h>

#include <cmath>
#include <cstdio>
#include <iostream>
#include <mutex>
#include <new>

namespace canopy {
namespace {
std::atomic<bool> gQuiet{false};
std::mutex gStderrMutex;
std::string gToolName;  // set by Tool: warnings read "canopy-x: warning: ..." like its errors

const char* kExitCodes =
    "Exit codes: 0 ok, 1 usage, 2 I/O error, 3 invalid input, 4 runtime failure, 5 unsupported.";
}  // namespace

void setQuiet(bool q) { gQuiet = q; }
bool isQuiet() { return gQuiet; }

void logInfo(const std::string& m) {
  if (gQuiet) return;
  std::lock_guard<std::mutex> lock(gStderrMutex);
  std::cerr << m << '\n';
}

void logWarn(const std::string& m) {
  std::lock_guard<std::mutex> lock(gStderrMutex);
  std::cerr << (gToolName.empty() ? "" : gToolName + ": ") << "warning: " << m << '\n';
}

double secondsSince(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

Tool::Tool(std::string name, std::string description, bool withDevice)
    : name_(std::move(name)), program_(name_.substr(0, name_.find(' '))), app_(std::move(description), name_) {
  gToolName = program_;
  app_.set_version_flag("--version", program_ + " " + versionString());
  app_.add_flag("-q,--quiet", common_.quiet, "No progress or log output on stderr");
  app_.add_flag("--json", common_.json, "Print one JSON report object on stdout");
  if (withDevice)
    app_.add_option("--device", common_.device, "auto, cpu, cuda (all GPUs) or cuda:N")
        ->capture_default_str();
  app_.footer(kExitCodes);
}

int Tool::run(int argc, char** argv, const std::function<void()>& body) {
  try {
    app_.parse(argc, argv);
  } catch (const CLI::CallForHelp& e) {
    return app_.exit(e);
  } catch (const CLI::CallForAllHelp& e) {
    return app_.exit(e);
  } catch (const CLI::CallForVersion& e) {
    return app_.exit(e);
  } catch (const CLI::ParseError& e) {
    std::cerr << program_ << ": error: " << e.what() << " (see " << name_ << " --help)\n";
    return int(ExitCode::Usage);
  }
  setQuiet(common_.quiet);
  int code = 0;
  try {
    InputTracking tracking;  // an output may not replace a file this run reads (atomic_file.h)
    body();
  } catch (const Error& e) {
    std::cerr << program_ << ": error: " << e.what() << (e.code() == ExitCode::Usage ? " (see " + name_ + " --help)" : std::string()) << '\n';
    code = int(e.code());
  } catch (const std::bad_alloc&) {
    std::cerr << program_ << ": error: out of memory\n";
    code = int(ExitCode::Runtime);
  } catch (const std::exception& e) {
    std::cerr << program_ << ": error: " << e.what() << '\n';
    code = int(ExitCode::Runtime);
  }
  if (common_.json) {
    report_["tool"] = program_;
    report_["version"] = versionString();
    report_["exit_code"] = code;
    std::cout << report_.dump(2) << std::endl;
  }
  return code;
}

Progress::Progress(std::string label, int64_t total)
    : label_(std::move(label)), total_(total < 1 ? 1 : total),
      enabled_(!isQuiet() && isatty(STDERR_FILENO)), start_(std::chrono::steady_clock::now()) {}

Progress::~Progress() { done(); }

void Progress::add(int64_t n) {
  count_ += n;
  if (enabled_) draw(false);
}

void Progress::draw(bool force) {
  int64_t ms = int64_t(secondsSince(start_) * 1000);
  int64_t last = lastDrawMs_.load();
  if (!force && (ms - last < 100 || !lastDrawMs_.compare_exchange_strong(last, ms))) return;
  double f = std::min(1.0, double(count_.load()) / double(total_));
  int filled = int(f * 30);
  std::lock_guard<std::mutex> lock(gStderrMutex);
  std::fprintf(stderr, "\r%-24s [%.*s%*s] %5.1f%% %6.1fs", label_.c_str(), filled,
               "##############################", 30 - filled, "", 100 * f, ms / 1000.0);
  std::fflush(stderr);
}

void Progress::done() {
  if (finished_) return;
  finished_ = true;
  if (!enabled_) return;
  count_ = total_;
  draw(true);
  std::lock_guard<std::mutex> lock(gStderrMutex);
  std::fputc('\n', stderr);
}

}  // namespace canopy
