// Starts the HTML report tool (python3 -m cdm.report) with an argument
// vector: no shell, so any path (quotes, spaces, `$`) reaches it verbatim.
// The package Python imports (wheel or .deb) is preferred; then the places
// beside this executable (package_dirs): nothing of the build machine's paths
// is compiled in.
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "report.h"

extern char **environ;

namespace cdm::cli {

namespace {

// Spawns argv with environ plus `extra` (NAME=value entries, replacing any
// same-named entry); returns the exit status, or -1 with errno when the
// program could not be started.
int spawn_wait(const std::vector<std::string> &args, const std::vector<std::string> &extra) {
    std::vector<char *> argv;
    for (const auto &a : args) argv.push_back(const_cast<char *>(a.c_str()));
    argv.push_back(nullptr);
    std::vector<char *> envp;
    for (char **e = environ; *e; ++e) {
        bool replaced = false;
        for (const auto &x : extra)
            if (std::strncmp(*e, x.c_str(), x.find('=') + 1) == 0) replaced = true;
        if (!replaced) envp.push_back(*e);
    }
    for (const auto &x : extra) envp.push_back(const_cast<char *>(x.c_str()));
    envp.push_back(nullptr);
    // What this process printed so far goes out before the child's output
    // (a pipe or a file buffers stdout: without this the child's lines come
    // first and ours after it exits).
    std::fflush(stdout);
    std::fflush(stderr);
    pid_t pid = 0;
    const int rc = posix_spawnp(&pid, argv[0], nullptr, nullptr, argv.data(), envp.data());
    if (rc != 0) {
        errno = rc;
        return -1;
    }
    int status = 0;
    while (waitpid(pid, &status, 0) < 0)
        if (errno != EINTR) return -1;
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

// A path as an argument the child cannot take for an option: one that
// starts with '-' gets "./" before it (the same file).
std::string path_arg(const std::string &p) { return !p.empty() && p[0] == '-' ? "./" + p : p; }

// Exit 0 when `python` can import the report with its dependencies; else 3,
// and with "-v" the missing module's name on stderr (no traceback).
const char *const kProbe = "import sys\n"
                           "try:\n"
                           "    import cdm.report\n"
                           "except ImportError as e:\n"
                           "    if sys.argv[1:] == ['-v']:\n"
                           "        sys.stderr.write('cdm: missing Python module: %s\\n' % (e.name or e))\n"
                           "    sys.exit(3)\n";

// Where the cdm Python package may be, found from this executable's own path:
// the file cdm-pythonpath beside it (written by the build tree, naming the
// sources' bindings/python; never installed), then an installed tree's
// ../lib/python3/dist-packages (the .deb's /usr/lib/python3/dist-packages),
// then, for the wheel's SITE/cdm/bin/cdm, the SITE the package is in.
std::vector<std::string> package_dirs() {
    std::vector<std::string> out;
    std::vector<char> buf(4096);
    const ssize_t n = readlink("/proc/self/exe", buf.data(), buf.size() - 1);
    if (n <= 0)
        return out;
    const std::string exe(buf.data(), static_cast<size_t>(n));
    const std::string dir = exe.substr(0, exe.rfind('/'));
    std::ifstream f(dir + "/cdm-pythonpath");
    std::string line;
    if (f && std::getline(f, line) && !line.empty())
        out.push_back(line);
    out.push_back(dir + "/../lib/python3/dist-packages");
    const std::string wheel_bin = "/cdm/bin";
    if (dir.size() > wheel_bin.size() && dir.compare(dir.size() - wheel_bin.size(), wheel_bin.size(), wheel_bin) == 0)
        out.push_back(dir.substr(0, dir.size() - wheel_bin.size()));
    return out;
}

} // namespace

int run_report(const std::string &json_path, const std::vector<std::string> &before, const std::string &dir,
               bool claim) {
    const char *env_py = std::getenv("PYTHON");
    const std::string py = env_py && *env_py ? env_py : "python3";
    std::vector<std::string> env;
    int probe = spawn_wait({py, "-c", kProbe}, env);
    if (probe < 0) {
        std::fprintf(stderr, "cdm: --report: cannot run %s: %s (set PYTHON to the Python 3 to use)\n", py.c_str(),
                     std::strerror(errno));
        return 1;
    }
    for (const std::string &src : package_dirs()) {
        struct stat st {};
        if (probe == 0 || stat((src + "/cdm/report/__init__.py").c_str(), &st) != 0)
            continue;
        const char *pp = std::getenv("PYTHONPATH");
        env.assign({"PYTHONPATH=" + src + (pp && *pp ? ":" + std::string(pp) : "")});
        probe = spawn_wait({py, "-c", kProbe}, env);
    }
    if (probe != 0) {
        spawn_wait({py, "-c", kProbe, "-v"}, env); // names what is missing
        std::fprintf(stderr,
                     "cdm: --report needs the cdm Python package with numpy and matplotlib for %s: install them "
                     "with `pip install 'cdm-haptics[report]'` (from a clone: `pip install '.[report]'`; with the "
                     "cdm .deb: `apt install python3-numpy python3-matplotlib`), or set PYTHON to a Python 3 that "
                     "has them\n",
                     py.c_str());
        return 1;
    }
    std::vector<std::string> args{py, "-m", "cdm.report"};
    for (const std::string &b : before) args.push_back(path_arg(b));
    args.insert(args.end(), {path_arg(json_path), "--out", path_arg(dir)});
    if (claim) args.push_back("--claim");
    const int rc = spawn_wait(args, env);
    if (rc != 0) {
        std::fprintf(stderr, "cdm: --report: %s -m cdm.report failed (exit status %d)\n", py.c_str(), rc);
        return 1;
    }
    return 0;
}

} // namespace cdm::cli
