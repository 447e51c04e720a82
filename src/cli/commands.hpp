// Subcommands of the bouncecal executable. Each Register* adds one subcommand to the app; its
// callback does the work and throws bouncecal::Error on failure (main prints it and exits with
// its code). Output: human-readable on stdout by default, --json / --csv for scripts;
// messages and progress on stderr only.
#pragma once

#include <CLI/CLI.hpp>

namespace bouncecal::cli {

void RegisterDetect(CLI::App& app);
void RegisterAnalyze(CLI::App& app);
void RegisterSynth(CLI::App& app);
void RegisterLaws(CLI::App& app);
void RegisterSimulate(CLI::App& app);
void RegisterCalibrate(CLI::App& app);
void RegisterExport(CLI::App& app);
void RegisterReport(CLI::App& app);
void RegisterServe(CLI::App& app);
void RegisterListen(CLI::App& app);

}  // namespace bouncecal::cli
