"""Dotted keys into nested settings: read, removed and set without touching the original."""

from tactile_exp import dotted


def test_get_without_and_assign_walk_dotted_keys():
    params = {"schedule": {"epochs": 2, "head": {"lr": 0.1}}, "impl": "torch"}
    assert dotted.get(params, "schedule.head.lr") == 0.1
    assert dotted.get(params, "schedule.missing") is dotted.MISSING
    assert dotted.get(params, "impl.deeper") is dotted.MISSING  # a value, not a mapping
    out = dotted.without(params, ("schedule.head", "impl", "absent.key"))
    assert out == {"schedule": {"epochs": 2}}
    assert params["schedule"]["head"] == {"lr": 0.1} and "impl" in params  # left as it was
    copy = {"schedule": params["schedule"]}
    dotted.assign(copy, "schedule.head.lr", 0.5)
    assert copy["schedule"]["head"] == {"lr": 0.5} and params["schedule"]["head"] == {"lr": 0.1}
    dotted.assign(copy, "new.leaf", 1)
    assert copy["new"] == {"leaf": 1}
