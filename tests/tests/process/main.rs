//! Tests whose subject is the whole test process: a SIGTERM raised in it (`termination_*`), its
//! alarm thread (`alarm_timeouts`), every heap allocation it makes (`no_alloc_*`, through the
//! counting global allocator installed here); and the binaries' command lines against what the
//! documentation shows (`docs_commands`: they run only `--help` and `check-config`). Each test runs in a process of its own
//! (`navsync_tests::in_own_process!`: the binary starts itself again with only that test), so a
//! signal raised by one never reaches another and an allocation counted is the test's own.

#[global_allocator]
static GLOBAL: navsync_tests::CountingAllocator = navsync_tests::CountingAllocator;

mod alarm_timeouts;
mod docs_commands;
mod no_alloc_drivers;
mod no_alloc_history;
mod no_alloc_tight;
mod termination_latch;
mod termination_sleep;
mod termination_untimed;
mod termination_wait;
