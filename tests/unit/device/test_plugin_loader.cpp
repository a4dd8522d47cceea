// cdm_effect_load_plugin: a bare name is refused (the dynamic
// linker's search path, e.g. LD_LIBRARY_PATH, must not pick the code), and a
// plugin whose init fails is unloaded again.
#include <dlfcn.h>

#include <cstring>
#include <string>

#include "cdm/cdm.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
extern "C" {
#include <cmocka.h>
}

namespace {

void test_plugin_bare_name_refused(void **) {
    // The failing plugin's own file name, without its directory: even if a
    // search path held it, it must not be looked up.
    const std::string full = CDM_TEST_PLUGIN_FAIL;
    const std::string bare = full.substr(full.rfind('/') + 1);
    assert_int_equal(cdm_effect_load_plugin(bare.c_str()), CDM_ERR_INVALID_ARG);
    assert_non_null(std::strstr(cdm_thread_error(), "bare name"));
    assert_null(dlopen(full.c_str(), RTLD_NOW | RTLD_NOLOAD)); // never loaded
}

void test_plugin_failed_init_unloads(void **) {
    const char *path = CDM_TEST_PLUGIN_FAIL;
    assert_int_equal(cdm_effect_load_plugin(path), CDM_ERR_INVALID_ARG);
    assert_non_null(std::strstr(cdm_thread_error(), "unloaded"));
    // RTLD_NOLOAD: a handle only if the library is still mapped.
    void *h = dlopen(path, RTLD_NOW | RTLD_NOLOAD);
    if (h) {
        dlclose(h);
        fail_msg("%s is still loaded after its init failed", path);
    }
}

void test_plugin_missing_file_names_reason(void **) {
    assert_int_equal(cdm_effect_load_plugin("./no_such_plugin.so"), CDM_ERR_IO);
    assert_non_null(std::strstr(cdm_thread_error(), "no_such_plugin.so"));
}

} // namespace

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_plugin_bare_name_refused),
        cmocka_unit_test(test_plugin_failed_init_unloads),
        cmocka_unit_test(test_plugin_missing_file_names_reason),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
