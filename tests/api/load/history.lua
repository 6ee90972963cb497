-- wrk: GET one of the paths listed (one a line) in the file named by PATHS
-- (env), chosen at random per request, with the key in KEY (env), so that a
-- run spreads over robots and sites instead of repeating one query.
local paths = {}
for line in io.lines(os.getenv("PATHS")) do
  if #line > 0 then paths[#paths + 1] = line end
end
assert(#paths > 0, "no paths")
math.randomseed(1)
wrk.headers["Authorization"] = "Bearer " .. os.getenv("KEY")

request = function()
  return wrk.format("GET", paths[math.random(#paths)])
end
-- wrk itself prints "Non-2xx or 3xx responses: N" when any answer was not
-- a success: the script greps for it.
