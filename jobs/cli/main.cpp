// The scanpress program: the command line of jobs/cli/cli.h.
#include "jobs/cli/cli.h"

int main(int argc, char** argv) { return scanpress::cliMain(argc, argv); }
