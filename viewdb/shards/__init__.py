"""Sharded catalogues: one catalogue split by object into several viewdb files, searched
exactly by scatter-gather over Ray actors.

:mod:`viewdb.shards.layout` (the files and the manifest, no Ray) and
:mod:`viewdb.shards.shard` (one shard answering in its process) import nothing beyond
viewdb; :mod:`viewdb.shards.cluster` needs the optional ``ray`` extra (``pip install
'viewdb[ray]'``) and is imported only when a sharded catalogue is served or searched.
"""
