// tools/process_time.hpp — whole-process timing for the benchmark programs: what a user waits
// for, start-up included (bench_simulate, bench_calibrate).
#pragma once

#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

namespace bouncecal::bench {

struct ProcessTime {
  double wall_s = 0.0, cpu_s = 0.0;  // cpu: the child's user + system time (wait4 rusage)
  int exit_code = -1;                // of the last run (-1: did not exit normally)
};

// A command: the program's path, then its arguments.
using Command = std::vector<std::string>;

// Runs the command once, output to /dev/null.
inline ProcessTime RunProcess(const Command& command) {
  std::vector<char*> argv;
  for (const std::string& a : command) argv.push_back(const_cast<char*>(a.c_str()));
  argv.push_back(nullptr);
  const auto t0 = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid == 0) {
    FILE* null = std::fopen("/dev/null", "w");
    if (null) {
      dup2(fileno(null), 1);
      dup2(fileno(null), 2);
    }
    execv(argv[0], argv.data());
    _exit(127);
  }
  ProcessTime t;
  int status = 0;
  rusage ru{};
  if (pid < 0 || wait4(pid, &status, 0, &ru) != pid) return t;
  t.wall_s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  t.cpu_s = static_cast<double>(ru.ru_utime.tv_sec + ru.ru_stime.tv_sec) +
            1e-6 * static_cast<double>(ru.ru_utime.tv_usec + ru.ru_stime.tv_usec);
  t.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return t;
}

// " (exit N)" after a command that did not exit with 0 (calibrate's outcomes have codes).
inline std::string ExitNote(const ProcessTime& t) {
  return t.exit_code == 0 ? "" : " (exit " + std::to_string(t.exit_code) + ")";
}

// Median wall and CPU time of each command over `runs` rounds; the commands take turns within a
// round, so that a change in the machine's load affects them alike (ratios stay comparable).
inline std::vector<ProcessTime> MedianProcesses(const std::vector<Command>& commands, int runs) {
  std::vector<std::vector<double>> wall(commands.size()), cpu(commands.size());
  std::vector<ProcessTime> out(commands.size());
  for (int r = 0; r < runs; ++r) {
    for (size_t c = 0; c < commands.size(); ++c) {
      const ProcessTime t = RunProcess(commands[c]);
      out[c].exit_code = t.exit_code;
      wall[c].push_back(t.wall_s);
      cpu[c].push_back(t.cpu_s);
    }
  }
  for (size_t c = 0; c < commands.size(); ++c) {
    std::sort(wall[c].begin(), wall[c].end());
    std::sort(cpu[c].begin(), cpu[c].end());
    out[c].wall_s = wall[c][wall[c].size() / 2];
    out[c].cpu_s = cpu[c][cpu[c].size() / 2];
  }
  return out;
}

// The bouncecal program next to this benchmark program (both are built into build/).
inline std::string ProgramNextToThis() {
  return (std::filesystem::read_symlink("/proc/self/exe").parent_path() / "bouncecal").string();
}

// "a b c" for a command's arguments (without the program).
inline std::string ArgumentLine(const Command& command) {
  std::string line;
  for (size_t i = 1; i < command.size(); ++i) line += (line.empty() ? "" : " ") + command[i];
  return line;
}

// Appends a copy of each command run by `baseline` (an older binary, BOUNCECAL_BASELINE) instead
// of the first word, so both are timed in the same loop; nothing without a baseline.
inline void AddBaselineCopies(std::vector<Command>* commands, const char* baseline) {
  if (!baseline) return;
  const std::size_t n = commands->size();
  for (std::size_t i = 0; i < n; ++i) {
    Command c = (*commands)[i];
    c[0] = baseline;
    commands->push_back(c);
  }
}

}  // namespace bouncecal::bench
