// with_master [--replug AFTER_MS,GAP_MS[,TIMES]] CMD [ARGS...]: runs CMD
// (spawned with an argument vector, no shell) while an emulated master is
// plugged in (master_testbed.h), and exits with CMD's status. Lets the `cdm`
// command and the bindings meet the real libhidapi-hidraw on /dev/hidraw0.
// With --replug, the master is unplugged AFTER_MS after the start and
// plugged back GAP_MS later, with the kernel's uevents (for `cdm list
// --watch` and reconnection tests); TIMES (default 1) repeats the unplug
// and replug, GAP_MS apart (a stress run for the watcher, by hand). Run
// through umockdev-wrapper: the child inherits the preload and $UMOCKDEV_DIR;
// this process serves its node's ioctls and reads.
//
// Its last line on stdout is "with_master: exit status N" (or "killed by
// signal S"): the tests match output with a regular expression, which
// ignores the exit status, so they match this line too and a child that
// printed everything and then crashed fails.
#include <spawn.h>
#include <sys/wait.h>

#include <cerrno>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <exception>
#include <thread>

#include "master_testbed.h"

extern char **environ;

int main(int argc, char **argv) {
    int first = 1, after_ms = -1, gap_ms = 0, times = 1;
    if (argc > 2 && std::strcmp(argv[1], "--replug") == 0) {
        char tail = 0;
        const int n = std::sscanf(argv[2], "%d,%d,%d%c", &after_ms, &gap_ms, &times, &tail);
        if ((n != 2 && n != 3) || after_ms < 0 || gap_ms < 0 || times < 1) {
            std::fprintf(stderr,
                         "with_master: --replug wants AFTER_MS,GAP_MS[,TIMES] (integers >= 0, TIMES >= 1), got \"%s\"\n",
                         argv[2]);
            return 2;
        }
        first = 3;
    }
    if (argc <= first) {
        std::fprintf(stderr, "usage: with_master [--replug AFTER_MS,GAP_MS[,TIMES]] CMD [ARGS...]\n");
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
            for (int k = 0; k < times; ++k) {
                if (k > 0) std::this_thread::sleep_for(std::chrono::milliseconds(gap_ms));
                tb.unplug();
                std::this_thread::sleep_for(std::chrono::milliseconds(gap_ms));
                tb.plug();
            }
        }
        int st = 0;
        while (waitpid(pid, &st, 0) < 0)
            if (errno != EINTR) {
                std::perror("with_master: waitpid");
                return 2;
            }
        std::fflush(stdout);
        if (WIFEXITED(st)) {
            std::printf("with_master: exit status %d\n", WEXITSTATUS(st));
            return WEXITSTATUS(st);
        }
        std::printf("with_master: killed by signal %d\n", WTERMSIG(st));
        return 128 + WTERMSIG(st);
    } catch (const std::exception &e) {
        std::fprintf(stderr, "with_master: %s\n", e.what());
        return 2;
    }
}
