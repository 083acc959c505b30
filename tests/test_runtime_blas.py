"""one_blas_thread: BLAS on one thread inside, the previous count restored after."""

from threadpoolctl import threadpool_info, threadpool_limits

from tactile_exp.runtime.blas import one_blas_thread


def _blas_threads() -> set[int]:
    return {lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"}


def test_one_thread_inside_and_the_count_restored_after():
    with threadpool_limits(2, user_api="blas"):  # whatever the test process's own count
        assert _blas_threads() == {2}
        with one_blas_thread():
            assert _blas_threads() == {1}
        assert _blas_threads() == {2}
