import pytest

from tactile_exp.registry import Registry


class Base:
    pass


def test_register_build_and_names():
    reg: Registry[Base] = Registry("widget", Base)

    @reg.register("b")
    class B(Base):
        def __init__(self, x: int = 1) -> None:
            self.x = x

    assert reg.names() == ["b"]
    assert "b" in reg and "c" not in reg
    assert reg.build("b", x=3).x == 3


def test_duplicate_and_wrong_base_rejected():
    reg: Registry[Base] = Registry("widget", Base)
    reg.register("a")(Base)
    with pytest.raises(ValueError, match="already has an entry named 'a'"):
        reg.register("a")(Base)
    with pytest.raises(TypeError, match="not a Base"):
        reg.register("int")(int)


def test_miss_names_registry_and_known_entries():
    reg: Registry[Base] = Registry("widget", Base)
    reg.register("alpha")(Base)
    reg.register("beta")(Base)
    with pytest.raises(KeyError, match="unknown widget 'gamma'; known widgets: alpha, beta"):
        reg["gamma"]


def test_temporary_entries_are_forgotten_when_the_block_ends():
    reg: Registry[Base] = Registry("widget", Base)
    reg.register("a")(Base)

    class Other(Base):
        pass

    with reg.temporary(a=Other) as inside:
        inside.register("b")(Base)
        assert reg.names() == ["a", "b"] and reg["a"] is Other
        with pytest.raises(TypeError, match="not a Base"):
            reg.register("int")(int)
    assert reg.names() == ["a"] and reg["a"] is Base
    with pytest.raises(RuntimeError, match="inside"), reg.temporary():
        reg.register("c")(Base)
        raise RuntimeError("inside")
    assert reg.names() == ["a"]
    with pytest.raises(TypeError, match="not a Base"), reg.temporary(x=int):  # type: ignore[arg-type]
        pass
    assert reg.names() == ["a"]
