"""Re-processing archives of many bags: ``ingest -> identify`` per bag, then ``track`` and, where the
structure file has parameters, ``update`` per structure, on a serial or a Dask engine
(``shm-ros batch``)."""
