// Replays a fuzz target's corpus without libFuzzer (any compiler): every
// file under the directories given goes through LLVMFuzzerTestOneInput once.
// ctest runs this for every target, so each crash a fuzzer ever found (kept
// in tests/fuzz/corpus/TARGET/) stays a test, in the plain and TSan builds
// (the ASan build is the fuzzing one: there the libFuzzer program replays the
// corpus itself, with -runs=0). A broken invariant aborts, which fails the test.
#include <dirent.h>
#include <sys/stat.h>

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

namespace {
int run_path(const std::string &path) {
    struct stat st {};
    if (stat(path.c_str(), &st) != 0) {
        std::fprintf(stderr, "corpus: cannot stat %s\n", path.c_str());
        return -1;
    }
    if (S_ISDIR(st.st_mode)) {
        DIR *d = opendir(path.c_str());
        if (!d) return -1;
        int n = 0;
        while (dirent *e = readdir(d)) {
            const std::string name = e->d_name;
            if (name == "." || name == "..") continue;
            const int k = run_path(path + "/" + name);
            if (k < 0) {
                closedir(d);
                return -1;
            }
            n += k;
        }
        closedir(d);
        return n;
    }
    std::ifstream f(path, std::ios::binary);
    const std::vector<char> bytes((std::istreambuf_iterator<char>(f)), std::istreambuf_iterator<char>());
    LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t *>(bytes.data()), bytes.size());
    return 1;
}
} // namespace

int main(int argc, char **argv) {
    int total = 0;
    for (int i = 1; i < argc; ++i) {
        const int n = run_path(argv[i]);
        if (n < 0) return 1;
        total += n;
    }
    std::printf("corpus: %d inputs, every invariant held\n", total);
    return total > 0 ? 0 : 1; // an empty corpus tests nothing
}
