// with_master [--replug AFTER_MS,GAP_MS[,TIMES] [--after-output TEXT]] CMD [ARGS...]:
// runs CMD (spawned with an argument vector, no shell) while an emulated
// master is plugged in (master_testbed.h), and exits with CMD's status. Lets
// the `cdm` command and the bindings meet the real libhidapi-hidraw on
// /dev/hidraw0.
// With --replug, the master is unplugged AFTER_MS after the start and
// plugged back GAP_MS later, with the kernel's uevents (for `cdm list
// --watch` and reconnection tests); TIMES (default 1) repeats the unplug
// and replug, GAP_MS apart (a stress run for the watcher, by hand). Run
// through umockdev-wrapper: the child inherits the preload and $UMOCKDEV_DIR;
// this process serves its node's ioctls and reads.
//
// With --after-output TEXT, AFTER_MS counts from the moment CMD first
// prints TEXT on its stdout (which passes through this process), not from
// its start: a program that says when it is ready (a watcher's first
// "arrived", a stream's first report) meets the unplug ready, however long
// its runtime took to start. A Python or Mono program starting on a cold
// or loaded machine can take more than a fixed delay allows, see only the
// replug and fail. TEXT not printed
// within 20 s, or CMD's stdout closed first: said on stderr, and the
// re-plugs go ahead (the test then fails on what CMD saw).
//
// Its last line on stdout is "with_master: exit status N" (or "killed by
// signal S"): the tests match output with a regular expression, which
// ignores the exit status, so they match this line too and a child that
// printed everything and then crashed fails.
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <condition_variable>
#include <cstdio>
#include <cstring>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

#include "master_testbed.h"

extern char **environ;

namespace {

// The child's stdout, passed through to ours; `seen` once TEXT went by.
struct Relay {
    std::string text;
    std::mutex mu;
    std::condition_variable cv;
    bool seen = false, closed = false;

    void run(int fd) {
        std::string tail; // the last text.size() - 1 bytes: TEXT split across reads
        char buf[4096];
        for (;;) {
            const ssize_t n = ::read(fd, buf, sizeof buf);
            if (n < 0 && errno == EINTR) continue;
            if (n <= 0) break;
            std::fwrite(buf, 1, size_t(n), stdout);
            std::fflush(stdout);
            std::lock_guard<std::mutex> lk(mu);
            if (seen) continue;
            tail.append(buf, size_t(n));
            if (tail.find(text) != std::string::npos) {
                seen = true;
                cv.notify_all();
            } else if (tail.size() >= text.size()) {
                tail.erase(0, tail.size() - (text.size() - 1));
            }
        }
        ::close(fd);
        std::lock_guard<std::mutex> lk(mu);
        closed = true;
        cv.notify_all();
    }
};

} // namespace

int main(int argc, char **argv) {
    int first = 1, after_ms = -1, gap_ms = 0, times = 1;
    std::string after_output;
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
        if (argc > 4 && std::strcmp(argv[3], "--after-output") == 0) {
            after_output = argv[4];
            if (after_output.empty()) {
                std::fprintf(stderr, "with_master: --after-output wants a non-empty TEXT\n");
                return 2;
            }
            first = 5;
        }
    }
    if (argc <= first) {
        std::fprintf(stderr, "usage: with_master [--replug AFTER_MS,GAP_MS[,TIMES] [--after-output TEXT]] CMD [ARGS...]\n");
        return 2;
    }
    try {
        cdm_umock::MasterTestbed tb;
        // Static: on a way out that leaves the reader running (an
        // exception), it is detached and must not outlive what it writes.
        static Relay relay;
        relay.text = after_output;
        int pipefd[2] = {-1, -1};
        posix_spawn_file_actions_t fa;
        posix_spawn_file_actions_init(&fa);
        if (!after_output.empty()) {
            if (::pipe(pipefd) != 0) {
                std::perror("with_master: pipe");
                return 2;
            }
            posix_spawn_file_actions_adddup2(&fa, pipefd[1], STDOUT_FILENO);
            posix_spawn_file_actions_addclose(&fa, pipefd[0]);
            posix_spawn_file_actions_addclose(&fa, pipefd[1]);
        }
        std::fflush(stdout);
        pid_t pid;
        const int spawned = posix_spawnp(&pid, argv[first], &fa, nullptr, argv + first, environ);
        posix_spawn_file_actions_destroy(&fa);
        std::thread reader;
        struct Detach {
            std::thread &t;
            ~Detach() {
                if (t.joinable()) t.detach();
            }
        } detach_on_error{reader};
        if (pipefd[1] >= 0) {
            ::close(pipefd[1]);
            if (spawned == 0) reader = std::thread([fd = pipefd[0]] { relay.run(fd); });
            else ::close(pipefd[0]);
        }
        if (spawned != 0) {
            errno = spawned;
            std::perror(argv[first]);
            return 127;
        }
        if (after_ms >= 0) {
            if (!after_output.empty()) {
                std::unique_lock<std::mutex> lk(relay.mu);
                if (!relay.cv.wait_for(lk, std::chrono::seconds(20), [&] { return relay.seen || relay.closed; }) ||
                    !relay.seen)
                    std::fprintf(stderr, "with_master: \"%s\" not printed by %s (%s): re-plugging anyway\n",
                                 after_output.c_str(), argv[first],
                                 relay.closed ? "its output ended" : "20 s went by");
            }
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
        if (reader.joinable()) reader.join(); // the child's last output before our last line
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
