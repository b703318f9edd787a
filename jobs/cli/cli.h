// The scanpress command line (jobs/cli/cli.cpp), as a function: the `scanpress` program is only this, and the MPI
// build's `scanpress-mpi` (mpi/) runs it on rank 0.
#pragma once

namespace scanpress {

// Runs the command line; returns the process exit code: 0 ok, 1 usage or config error, 2 bad input data, 3
// environment (I/O, disk full), 4 internal error. Installs the process's signal handling (SIGXFSZ, SIGPIPE ignored;
// SIGINT, SIGTERM and SIGHUP remove temporaries, then end the process with 128 + the signal).
int cliMain(int argc, char** argv);

}  // namespace scanpress
