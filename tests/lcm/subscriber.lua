-- A Lua LCM client built from the lcm-gen types: prints every gaitmon message it receives as one
-- JSON line {"channel": ..., "type": ..., "message": {...}}, so tests in any language can check
-- what crossed the bus.
--
-- lua5.2 subscriber.lua --url URL --types LUA_DIR [--count N] [--timeout-s S] [CHANNEL=TYPE ...]
--
-- LUA_DIR is the lcm-gen Lua output (build/lcm/lua). Without CHANNEL=TYPE pairs it listens to the
-- seven default gaitmon channels. After subscribing it prints the line "ready"; it exits after N
-- messages, after S seconds (to the whole second), or when killed.
package.cpath = "/usr/lib/lua/5.2/?.so;" .. package.cpath

local url, types_dir, count, timeout_s = nil, nil, 0, 0
local routes = {}
local i = 1
while i <= #arg do
  local a = arg[i]
  if a == "--url" then url = arg[i + 1]; i = i + 2
  elseif a == "--types" then types_dir = arg[i + 1]; i = i + 2
  elseif a == "--count" then count = tonumber(arg[i + 1]); i = i + 2
  elseif a == "--timeout-s" then timeout_s = tonumber(arg[i + 1]); i = i + 2
  else
    local channel, type_name = a:match("^([^=]+)=([%w_]+)$")
    if not channel then
      io.stderr:write("subscriber.lua: bad argument " .. a .. "\n")
      os.exit(2)
    end
    routes[channel] = type_name
    i = i + 1
  end
end
if not url or not types_dir then
  io.stderr:write("usage: subscriber.lua --url URL --types LUA_DIR [--count N] [--timeout-s S] "
                  .. "[CHANNEL=TYPE ...]\n")
  os.exit(2)
end
if next(routes) == nil then
  routes = {GAITMON_FRAME = "frame_t", GAITMON_STEP = "step_t", GAITMON_FIT = "fit_t",
            GAITMON_STATUS = "status_t", GAITMON_RAW = "raw_t", GAITMON_EFFECTS = "effects_t",
            GAITMON_TISSUE = "tissue_t"}
end
package.path = types_dir .. "/?.lua;" .. types_dir .. "/?/init.lua;" .. package.path

local lcm = require("lcm")
local gaitmon = require("gaitmon")

-- Lua 5.2 numbers are doubles: integers (utime included, below 2^53) print as integers, others
-- with 17 significant digits so that they read back bit for bit.
local function number_json(x)
  if x ~= x or x == math.huge or x == -math.huge then return "null" end
  if x == math.floor(x) and math.abs(x) < 2^53 then return string.format("%d", x) end
  return string.format("%.17g", x)
end

local function string_json(s)
  return '"' .. s:gsub('[%c"\\]', function(c)
    return string.format("\\u%04x", c:byte())
  end) .. '"'
end

local function to_json(v)
  local t = type(v)
  if t == "number" then return number_json(v) end
  if t == "string" then return string_json(v) end
  if t == "boolean" then return tostring(v) end
  if t ~= "table" then return "null" end
  if next(v) == nil or v[1] ~= nil then
    local parts = {}
    for _, x in ipairs(v) do parts[#parts + 1] = to_json(x) end
    return "[" .. table.concat(parts, ",") .. "]"
  end
  local keys = {}
  for k in pairs(v) do keys[#keys + 1] = k end
  table.sort(keys)
  local parts = {}
  for _, k in ipairs(keys) do parts[#parts + 1] = string_json(k) .. ":" .. to_json(v[k]) end
  return "{" .. table.concat(parts, ",") .. "}"
end

io.stdout:setvbuf("line")
local lc = lcm.lcm.new(url)
local received = 0
for channel, type_name in pairs(routes) do
  local message_type = gaitmon[type_name]
  if not message_type then
    io.stderr:write("subscriber.lua: no type gaitmon." .. type_name .. "\n")
    os.exit(2)
  end
  -- LCM anchors the channel as a regular expression; escape everything but letters and digits.
  lc:subscribe(channel:gsub("[^%w_]", "\\%0"), function(ch, data)
    local ok, message = pcall(message_type.decode, data)
    if ok then
      print(string.format('{"channel":%s,"type":%s,"message":%s}', string_json(ch),
                          string_json(message_type.name), to_json(message)))
    else
      print(string.format('{"channel":%s,"error":%s}', string_json(ch),
                          string_json(tostring(message))))
    end
    received = received + 1
  end)
end
print("ready")

-- os.time() counts whole seconds, which is enough for a safety timeout.
local deadline = os.time() + math.ceil(timeout_s)
while count == 0 or received < count do
  if timeout_s > 0 and os.time() >= deadline then break end
  lc:handle_timeout(100)
end
