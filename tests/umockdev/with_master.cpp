// with_master [--replug AFTER_MS,GAP_MS] CMD [ARGS...]: runs CMD (spawned
// with an argument vector, no shell) while an emulated master is plugged in
// (master_testbed.h), and exits with CMD's status. Lets the `cdm` command
// and the bindings meet the real libhidapi-hidraw on /dev/hidraw0. With
// --replug, the master is unplugged AFTER_MS after the start and plugged
// back GAP_MS later, with the kernel's uevents (for `cdm list --watch` and
// reconnection tests). Run through umockdev-wrapper: the child inherits the
// preload and $UMOCKDEV_DIR; this process serves its node's ioctls and
// reads.
#include <spawn.h>
#include <sys/wait.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <thread>

#include "master_testbed.h"

extern char **environ;

int main(int argc, char **argv) {
    int first = 1, after_ms = -1, gap_ms = 0;
    if (argc > 2 && std::strcmp(argv[1], "--replug") == 0) {
        if (std::sscanf(argv[2], "%d,%d", &after_ms, &gap_ms) != 2 || after_ms < 0 || gap_ms < 0) {
            std::fprintf(stderr, "with_master: --replug wants AFTER_MS,GAP_MS (two integers >= 0), got \"%s\"\n",
                         argv[2]);
            return 2;
        }
        first = 3;
    }
    if (argc <= first) {
        std::fprintf(stderr, "usage: with_master [--replug AFTER_MS,GAP_MS] CMD [ARGS...]\n");
        return 2;
    }
    try {
        cdm_umock::MasterTestbed tb;
        pid_t pid;
        if (posix_spawnp(&pid, argv[first], nullptr, nullptr, argv + first, environ) != 0) {
            std::perror(argv[first]);
            return 127;
        }
        if (after_ms >= 0) {
            std::this_thread::sleep_for(std::chrono::milliseconds(after_ms));
            tb.unplug();
            std::this_thread::sleep_for(std::chrono::milliseconds(gap_ms));
            tb.plug();
        }
        int st = 0;
        waitpid(pid, &st, 0);
        return WIFEXITED(st) ? WEXITSTATUS(st) : 128 + WTERMSIG(st);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "with_master: %s\n", e.what());
        return 2;
    }
}
