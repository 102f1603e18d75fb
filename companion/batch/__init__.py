"""``companion batch``: replay and score every log of a fleet on a Dask cluster.

* :mod:`.flight` — one flight: replay it, score it (truth beside it, else against its
  own receiver), one row of plain values; any failure is an error row.
* :mod:`.table` — the rows as one table (Parquet with pyarrow, else CSV), in a fixed
  order and with fixed columns whatever the workers did.
* :mod:`.summary` — the fleet summary (text, JSON) and its plots.
* :mod:`.run` — the inputs, the cluster (local worker processes or a scheduler's),
  the progress bar, retries.
"""
