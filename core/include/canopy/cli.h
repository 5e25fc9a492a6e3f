// cli.h: the command-line layer every Canopy tool shares.
//
// A tool's main builds a canopy::Tool, adds its own options to tool.app() (CLI11), and calls
// tool.run(argc, argv, body). Tool provides --help, --version, --quiet, --json, --device; maps
// canopy::Error to the exit-code table of errors.h; prints "canopy-x: error: <message>" on stderr
// (usage errors end with "(see canopy-x --help)", still one line); and prints the JSON report (one object) on
// stdout when --json is given. stdout carries data only; logs and progress go to stderr.
#pragma once
#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <string>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "canopy/device.h"
#include "canopy/errors.h"

namespace canopy {

std::string versionString();  // e.g. "0.1.0"

struct CommonOptions {
  bool quiet = false;
  bool json = false;
  std::string device = "auto";
};

class Tool {
 public:
  Tool(std::string name, std::string description, bool withDevice = true);
  CLI::App& app() { return app_; }
  const std::string& name() const { return name_; }
  CommonOptions& common() { return common_; }
  // The report printed on stdout under --json; the body fills it.
  nlohmann::json& report() { return report_; }
  // Resolves --device (call inside the body).
  Device device() const { return resolveDevice(common_.device); }

  // Parses, runs body, returns the exit code. Never throws.
  int run(int argc, char** argv, const std::function<void()>& body);

 private:
  std::string name_;     // "canopy-x" or, for a subcommand with its own Tool, "canopy-x info"
  std::string program_;  // "canopy-x": the prefix of errors and warnings, the report's "tool"
  CLI::App app_;
  CommonOptions common_;
  nlohmann::json report_ = nlohmann::json::object();
};

// Logging to stderr; silent under --quiet (set by Tool::run).
void setQuiet(bool quiet);
bool isQuiet();
void logInfo(const std::string& message);
void logWarn(const std::string& message);

// A progress bar on stderr, shown only when stderr is a terminal and not quiet. Thread-safe add().
class Progress {
 public:
  Progress(std::string label, int64_t total);
  ~Progress();
  void add(int64_t n = 1);
  void done();

 private:
  void draw(bool force);
  std::string label_;
  int64_t total_;
  std::atomic<int64_t> count_{0};
  std::atomic<int64_t> lastDrawMs_{0};
  bool enabled_;
  bool finished_ = false;
  std::chrono::steady_clock::time_point start_;
};

// Seconds since t0 (for reports).
double secondsSince(std::chrono::steady_clock::time_point t0);

}  // namespace canopy
