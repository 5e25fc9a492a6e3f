// bench_usage.h: the benchmarks' one way of answering -h / --help (usage on stdout, exit 0) and of
// refusing what they do not understand (usage on stderr, exit 1).
#pragma once
#include <cstdio>
#include <cstring>

// True when some argument is -h or --help; `usage` is then printed on stdout (the caller exits 0).
inline bool benchHelpRequested(int argc, char** argv, const char* usage) {
  for (int i = 1; i < argc; ++i)
    if (std::strcmp(argv[i], "--help") == 0 || std::strcmp(argv[i], "-h") == 0) {
      std::fputs(usage, stdout);
      return true;
    }
  return false;
}

// Prints "NAME: WHAT" and the usage on stderr; returns the exit status of a usage error (1).
inline int benchUsageError(const char* name, const char* what, const char* usage) {
  std::fprintf(stderr, "%s: %s\n%s", name, what, usage);
  return 1;
}
