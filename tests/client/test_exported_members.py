"""The public API is exactly ``client.__all__``, sorted (as httpx pins its own)."""

import types

import client


def test_all_public_names_are_exported_and_sorted() -> None:
    public = [
        name for name, value in vars(client).items()
        if not name.startswith("_") and not isinstance(value, types.ModuleType)
    ]
    assert client.__all__ == sorted(public, key=str.casefold)


def test_public_objects_show_the_public_module() -> None:
    assert client.Client.__module__ == "client"
    assert client.SkyfixHTTPError.__module__ == "client"
    assert client.SolveResult.__module__ == "client.models"  # wire models keep their home


def test_exception_tree_has_one_root() -> None:
    errors = [getattr(client, n) for n in client.__all__
              if isinstance(getattr(client, n), type) and issubclass(getattr(client, n), Exception)]
    assert all(issubclass(e, client.SkyfixClientError) for e in errors)
    assert issubclass(client.SkyfixTimeoutError, client.SkyfixTransportError)
    assert issubclass(client.RecordingError, ValueError)


def test_exceptions_pickle() -> None:
    import pickle

    for exc in (client.SkyfixHTTPError(422, "bad", "camera"), client.SkyfixFrameError("f1", "bad", None, 413),
                client.SkyfixStreamError("gone", ["a", 2]),
                client.RecordingError("x", path="r.jsonl", line=3)):
        back = pickle.loads(pickle.dumps(exc))
        assert type(back) is type(exc) and str(back) == str(exc) and vars(back) == vars(exc)
