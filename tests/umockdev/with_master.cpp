// with_master CMD [ARGS...]: runs CMD (spawned with an argument vector, no
// shell) while an emulated master is plugged in (master_testbed.h), and
// exits with CMD's status. Lets the `cdm` command and the bindings meet the
// real libhidapi-hidraw on /dev/hidraw0. Run through umockdev-wrapper: the
// child inherits the preload and $UMOCKDEV_DIR; this process serves its
// node's ioctls and reads.
#include <spawn.h>
#include <sys/wait.h>

#include <cstdio>
#include <exception>

#include "master_testbed.h"

extern char **environ;

int main(int argc, char **argv) {
    if (argc < 2) {
        std::fprintf(stderr, "usage: with_master CMD [ARGS...]\n");
        return 2;
    }
    try {
        cdm_umock::MasterTestbed tb;
        pid_t pid;
        if (posix_spawnp(&pid, argv[1], nullptr, nullptr, argv + 1, environ) != 0) {
            std::perror(argv[1]);
            return 127;
        }
        int st = 0;
        waitpid(pid, &st, 0);
        return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "with_master: %s\n", e.what());
        return 2;
    }
}
