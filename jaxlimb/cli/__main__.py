from . import entry

if __name__ == "__main__":  # guarded: Dask worker processes (spawn) import the main module
    raise SystemExit(entry())
