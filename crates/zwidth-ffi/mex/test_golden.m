% The MEX gateway against zwidth-dsp's golden vectors, bit for bit, and its
% refusals (crates/zwidth-ffi/tests/octave.rs runs it in Octave).
% usage: test_golden('crates/zwidth-dsp/golden/vectors.txt')
function test_golden(path)
  f = fopen(path, 'r');
  assert(f > 0, ['cannot open ' path]);
  line = fgetl(f);
  assert(strcmp(line, 'zwidth-dsp golden vectors 1'));
  cases = 0;
  pos = []; filled = 0; expect = {}; name = ''; signal = ''; stride = 1; v = [];
  while true
    line = fgetl(f);
    if ~ischar(line), break; end
    if isempty(line) || line(1) == '#', continue; end
    switch line(1)
      case 's'   % signal NAME RATE Q N
        check_case(name, signal, v, stride, expect); expect = {};
        w = strsplit(line, ' ');
        signal = w{2}; rate = str2double(w{3}); q = str2double(w{4});
        pos = zeros(str2double(w{5}), 1); filled = 0;
      case 'p'
        filled = filled + 1; pos(filled) = hex2num(line(3:end));
      case 'r'
        w = strsplit(line, ' ');
        c = str2double(w{2});
        pos(filled+1:filled+c) = hex2num(w{3}); filled = filled + c;
      case 'e'   % estimator NAME STRIDE HASH SPEC
        check_case(name, signal, v, stride, expect);
        w = strsplit(line, ' ');
        name = w{2}; stride = str2double(w{3});
        spec = strjoin(w(5:end), ' ');
        v = zw_estimate(spec, rate, q, pos);
        assert(isequal(size(v), size(pos)), [name ': shape']);
        expect = {};
        cases = cases + 1;
      case 'v'
        expect{end+1} = line(3:end); %#ok<AGROW>
    end
  end
  check_case(name, signal, v, stride, expect);
  fclose(f);
  assert(cases == 90, sprintf('read %d cases of 90', cases));

  refusals = 0;
  refusals = refusals + refuse('{"kind":', 1e3, 1e-6, [0 1], 'spec_json');
  refusals = refusals + refuse('{"kind":"butterworth","cutoff_hz":600}', 1e3, 1e-6, [0 1], 'cutoff_hz');
  refusals = refusals + refuse('{"kind":"foaw","fit":"end","max_window":100}', 1e3, 1e-6, [0 1], 'max_window');
  refusals = refusals + refuse('{"kind":"fdm"}', NaN, 1e-6, [0 1], 'rate');
  refusals = refusals + refuse('{"kind":"fdm"}', 1e3, 1e-6, [0 NaN], 'positions');
  refusals = refusals + refuse('{"kind":"fdm"}', 1e3, 1e-6, ones(2, 2), 'positions');
  refusals = refusals + refuse(42, 1e3, 1e-6, [0 1], 'spec');
  % A row in, a row out; FDM of [0 1e-3] at 1 kHz is [0 1].
  assert(isequal(zw_estimate('{"kind":"fdm"}', 1e3, 1e-6, [0 1e-3]), [0 1]));
  printf('octave: %d cases equal, %d refusals checked\n', cases, refusals);

end

function check_case(name, signal, v, stride, expect)
  if isempty(expect), return; end
  got = v(1:stride:end);
  assert(numel(got) == numel(expect), [name ': count']);
  for i = 1:numel(got)
    if ~strcmpi(num2hex(got(i)), expect{i})
      error('%s on %s: output %d is %s, the vectors say %s', name, signal, ...
            (i-1)*stride, num2hex(got(i)), expect{i});
    end
  end
end

function n = refuse(spec, rate, q, y, what)
  try
    zw_estimate(spec, rate, q, y);
    error('zwidth:test', 'no error for %s', what);
  catch e
    assert(~strcmp(e.identifier, 'zwidth:test'), e.message);
    assert(~isempty(strfind(e.message, what)), [what ': ' e.message]);
    assert(isempty(strfind(e.message, 'NaN')), e.message);
  end
  n = 1;
end
