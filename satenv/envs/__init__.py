"""satenv's PettingZoo environments (one versioned module per env)."""
