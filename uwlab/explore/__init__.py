"""The design explorer: a local web page over the design model (`uwlab explore`; docs/explorer.md)."""
