"""The ``pseudolight`` command line (:mod:`.main`; its entry point :func:`.entry.run`) and the
benchmark runner. Kept free of imports, so the entry point's signal handler is in place before
the command line's heavy imports begin."""
