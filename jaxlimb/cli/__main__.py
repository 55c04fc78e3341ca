from . import main

if __name__ == "__main__":  # guarded: Dask worker processes (spawn) import the main module
    raise SystemExit(main())
