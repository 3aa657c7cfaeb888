"""cvt.threads.one_ahead: the items of an iterable, made one ahead on the pool."""

import threading

import pytest

from compact_distributions.cvt import threads


@pytest.fixture
def two_cores(monkeypatch):
    monkeypatch.setattr(threads, "usable_cores", lambda: 2)


def test_one_ahead_gives_every_item_in_order_made_on_the_pool(two_cores):
    makers = []

    def source():
        for k in range(50):
            makers.append(threading.current_thread().name)
            yield k * k

    assert list(threads.one_ahead(source())) == [k * k for k in range(50)]
    assert len(makers) == 50 and all(name.startswith("elementwise") for name in makers)


def test_one_ahead_is_at_most_one_item_ahead_of_its_reader(two_cores):
    made = []

    def source():
        for k in range(10):
            made.append(k)
            yield k

    read = threads.one_ahead(source())
    for k in range(5):
        assert next(read) == k
        threads._shared_pool(2).submit(lambda: None).result()  # the pool has caught up
        assert len(made) <= k + 2
    read.close()
    assert len(made) <= 6  # closing stops the making


def test_one_ahead_raises_the_sources_error_where_it_is_read(two_cores):
    def source():
        yield 1
        raise ValueError("band 2 failed")

    read = threads.one_ahead(source())
    assert next(read) == 1
    with pytest.raises(ValueError, match="band 2 failed"):
        next(read)


def test_one_ahead_on_one_core_reads_in_this_thread(monkeypatch):
    monkeypatch.setattr(threads, "usable_cores", lambda: 1)
    names = []

    def source():
        for k in range(3):
            names.append(threading.current_thread().name)
            yield k

    assert list(threads.one_ahead(source())) == [0, 1, 2]
    assert names == [threading.current_thread().name] * 3
