/* Size and field offsets of every public struct, as the compiler lays them out,
 * against the hand-written table tests/data/abi_layout.json (shared with the
 * Python and C# layout tests). A change here is an ABI break. */
#ifndef CDM_EXPERIMENTAL
#define CDM_EXPERIMENTAL
#endif
#include "cdm/cdm.h"

#include <setjmp.h>
#include <stdarg.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <string.h>

#include <cmocka.h>

struct layout_row {
    const char *type;
    const char *field; /* "(size)" for the struct's size */
    size_t expected;
    size_t actual;
};

static const struct layout_row rows[] = {
#include "abi_layout_table.h"
};

static void test_table_matches_compiler(void **state) {
    (void)state;
    int failures = 0;
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++) {
        if (rows[i].expected != rows[i].actual) {
            print_error("%s.%s: table says %zu, compiler says %zu\n", rows[i].type, rows[i].field,
                        rows[i].expected, rows[i].actual);
            failures++;
        }
    }
    assert_int_equal(failures, 0);
}

/* Every struct of the table made it into the generated rows, and every public
 * struct with a struct_size field is in the table (a new struct that nobody
 * added to the table would otherwise pass unchecked). */
static void test_table_covers_public_structs(void **state) {
    (void)state;
    static const char *const public_structs[] = {"cdm_pose",         "cdm_raw",    "cdm_device_info",
                                                 "cdm_stats",        "cdm_sample", "cdm_open_options",
                                                 "cdm_effect_def",   "cdm_effect_context"};
    size_t n_sizes = 0;
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++)
        if (strcmp(rows[i].field, "(size)") == 0) n_sizes++;
    assert_int_equal(n_sizes, CDM_LAYOUT_STRUCT_COUNT);
    for (size_t s = 0; s < sizeof public_structs / sizeof public_structs[0]; s++) {
        int found = 0;
        for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++)
            if (strcmp(rows[i].type, public_structs[s]) == 0 && strcmp(rows[i].field, "(size)") == 0)
                found = 1;
        if (!found) print_error("%s is missing from tests/data/abi_layout.json\n", public_structs[s]);
        assert_true(found);
    }
}

/* struct_size leads every struct: the library relies on reading it first. */
static void test_struct_size_first(void **state) {
    (void)state;
    for (size_t i = 0; i < sizeof rows / sizeof rows[0]; i++)
        if (strcmp(rows[i].field, "struct_size") == 0) assert_int_equal(rows[i].actual, 0);
}

int main(void) {
    const struct CMUnitTest tests[] = {
        cmocka_unit_test(test_table_matches_compiler),
        cmocka_unit_test(test_table_covers_public_structs),
        cmocka_unit_test(test_struct_size_first),
    };
    return cmocka_run_group_tests(tests, NULL, NULL);
}
