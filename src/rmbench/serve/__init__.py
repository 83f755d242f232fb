"""Policies over a websocket: the server (``rmbench serve``) and the ``remote:`` client."""
